"""Each view pair's registration as a Dask task (issue 21): the pair mapper a session task of
:mod:`rangekit.app.batch.sessions` hands to :func:`rangekit.app.process.process.process_session`.

In every refinement round, :func:`rangekit.registration.multiview.register_views` maps its pair jobs
(:class:`rangekit.registration.pair_refine.PairJob`) through it: the round's downsampled clouds are
scattered to the cluster once, each pair is one task (:func:`rangekit.registration.pair_refine.refine_pair`,
ahead of every other task), and the session task waits for them off its worker's thread
(``distributed.worker_client``), so its own worker runs pairs too. A pair's result depends only on its job and
its two clouds, so the poses are the bits of serial processing.

If the cluster loses a round (a worker holding the scattered clouds dies), the round is redone in the
session task, one pair after another: the same results, later. A pair that fails for a reason of its own
(a view too sparse) is the session's error, as in serial processing.
"""

from __future__ import annotations

from typing import Sequence

__all__ = ["PAIR_PRIORITY", "dask_pair_mapper"]

#: Dask priority of the pair tasks: ahead of every view and session task (rangekit.app.batch.sessions), since a
#: session task waits for them.
PAIR_PRIORITY = 1 << 30


def dask_pair_mapper(progress=None):
    """A :data:`rangekit.registration.pair_refine.PairMapper` that runs each pair as a task on the cluster of
    the worker it is called on (from inside a Dask task). ``progress(msg)``: told when a round is redone here."""

    def map_pairs(jobs: Sequence, clouds: Sequence) -> list:
        from distributed import worker_client

        from rangekit.errors import RangekitError
        from rangekit.registration.pair_refine import refine_pair

        if not jobs:
            return []
        try:
            with worker_client() as client:
                used = sorted({k for job in jobs for k in (job.i, job.j)})
                scattered = dict(zip(used, client.scatter([clouds[k] for k in used])))
                futures = [client.submit(refine_pair, job, scattered[job.i], scattered[job.j], pure=False,
                                         priority=PAIR_PRIORITY) for job in jobs]
                return client.gather(futures)
        except RangekitError:    # a pair's own failure (a view too sparse): the session's error, as serially
            raise
        except Exception as e:   # the round lost on the cluster (a worker died, ...): redone here, the same results
            if progress is not None:
                progress(f"pair tasks lost ({type(e).__name__}): the round's {len(jobs)} pairs are redone here")
            return [refine_pair(job, clouds[job.i], clouds[job.j]) for job in jobs]

    return map_pairs
