"""The web app's one notifier (issue 49, 2): changes said from any thread wake the sockets waiting in the event
loop, fold per topic (the last version of each), and a page's loop gone away leaves the jobs saying theirs."""

from __future__ import annotations

import asyncio
import threading

from rangekit.ui.jobs.notifier import Changed, Notifier, Topic


def test_a_change_from_another_thread_wakes_every_waiter_and_folds_per_topic():
    notifier = Notifier()

    async def main():
        seen = notifier.version
        waiters = [asyncio.ensure_future(notifier.wait(seen)) for _ in range(3)]
        await asyncio.sleep(0)
        assert not any(w.done() for w in waiters)          # nothing changed: nobody wakes
        worker = threading.Thread(target=lambda: [notifier.changed(t) for t in
                                                  (Topic.CHECK, Topic.RIG, Topic.CHECK, Topic.CHECK)])
        worker.start()
        await asyncio.wait_for(asyncio.gather(*waiters), 30)
        worker.join()
        return notifier.since(seen)

    version, changes = asyncio.run(main())
    assert version == 4 and changes == [Changed(Topic.RIG, 2), Changed(Topic.CHECK, 4)]
    assert notifier.since(version) == (4, [])


def test_a_wait_past_the_version_returns_at_once_and_a_closed_loop_is_left_alone():
    notifier = Notifier()
    notifier.changed(Topic.REGISTER)

    async def already():
        await notifier.wait(0)                  # the version is 1 already: returns without a change
        return True

    assert asyncio.run(already())
    loop = asyncio.new_event_loop()
    task = loop.create_task(notifier.wait(notifier.version))
    loop.run_until_complete(asyncio.sleep(0))   # the waiter registered, then its loop closed (a page gone)
    loop.close()
    notifier.changed(Topic.CALIBRATE)           # no error: the job that says it goes on
    assert notifier.since(1) == (2, [Changed(Topic.CALIBRATE, 2)]) and not task.done()
