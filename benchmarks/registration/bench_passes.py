"""Registration CPU seconds per view of processed sessions, one pass or several (multi-pass scans, docs/passes.md).

    PYTHONPATH=. .venv/bin/python -m rangekit scan --out /tmp/s12 --no-process                 # 12 views
    PYTHONPATH=. .venv/bin/python -m rangekit scan --views 36 --out /tmp/s36 --no-process      # 36 views
    PYTHONPATH=. .venv/bin/python -m rangekit scan --views 36 --passes 2 --out /tmp/s72 --no-process
    PYTHONPATH=. .venv/bin/python -m rangekit process /tmp/s12    # (and the others: their clouds are cached)
    PYTHONPATH=. .venv/bin/python benchmarks/registration/bench_passes.py /tmp/s12 /tmp/s36 /tmp/s72 [--repeat 2]

Each session's ``view_*/cloud.ply`` (what ``rangekit process`` registers) is registered as processing does
(one pass: ``register_views`` with the turntable prior; several: ``register_passes``, the later passes
found without a prior), in this one process, sessions alternating, charged CPU seconds (user + sys,
``resource.getrusage``; the machine is shared), the minimum of ``--repeat`` runs. The pose errors are
against the simulator's truth (the turntable angles and, for several passes, the recorded turn-over).
"""

from __future__ import annotations

import argparse
import resource
import sys
from pathlib import Path

import numpy as np

from rangekit.formats.clouds import load_cloud
from rangekit.formats.sessions.session import Session
from rangekit.geometry import invert_T, rotation_angle


def cpu_seconds() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def register(session: Session, clouds):
    from rangekit.app.process.register import register_session_passes
    from rangekit.registration.multiview import MultiViewOptions, register_views
    from rangekit.rig.rig_file import turntable_prior

    views = session.done_views
    if session.plan.passes > 1:
        return register_session_passes(clouds, views, session.rig).T_world_view
    prior = turntable_prior(session.rig.T_world_table, [v.angle for v in views])
    return register_views(clouds, init_T_world_view=prior, options=MultiViewOptions(turntable=True)).T_world_view


def truth(session: Session) -> np.ndarray:
    from rangekit.sim.scene.passes import view_motions

    views, F = session.done_views, session.simulator.pass_motions
    keys = [v.angle for v in views] if F is None else [(v.angle, v.scan_pass) for v in views]
    M = view_motions(session.rig, keys, None if F is None else np.array(F))
    return np.stack([M[0] @ invert_T(Mk) for Mk in M])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sessions", nargs="+")
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args(argv)
    data = []
    for folder in args.sessions:
        s = Session.load(folder)
        data.append((s, [load_cloud(Path(v.folder) / "cloud.ply") for v in s.done_views]))
    best = {f: np.inf for f in args.sessions}
    errors = {}
    for _ in range(args.repeat):
        for folder, (s, clouds) in zip(args.sessions, data):
            t = cpu_seconds()
            T = register(s, clouds)
            best[folder] = min(best[folder], cpu_seconds() - t)
            Tt = truth(s)
            errors[folder] = (max(np.degrees(rotation_angle(a[:3, :3].T @ b[:3, :3])) for a, b in zip(T, Tt)),
                              max(np.linalg.norm(a[:3, 3] - b[:3, 3]) for a, b in zip(T, Tt)) * 1e3)
    base = None
    for folder, (s, _) in zip(args.sessions, data):
        n = len(s.done_views)
        per = best[folder] / n
        base = base or per
        print(f"{folder}: {n} views in {s.plan.passes} pass(es): registration {best[folder]:.1f} CPU-s, "
              f"{per:.2f} CPU-s per view ({per / base:.2f}x the first); pose error max {errors[folder][0]:.4f} deg, "
              f"{errors[folder][1]:.4f} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
