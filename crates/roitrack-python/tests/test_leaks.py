"""No reference leaks: 100,000 pushes (and refused ones, and repeated track() calls) leave every reference count and
the Python heap as they were."""

import gc
import sys
import threading
import time
import tracemalloc

import numpy as np

import roitrack


def test_no_reference_leak_over_100000_pushes() -> None:
    sim = roitrack.simulate("orthoglide", seed=2, rate_hz=21000.0)
    rows = sim["measurements"].tolist()
    assert len(rows) >= 102_000
    camera, target = sim["camera"], sim["target"]
    tracker = roitrack.Tracker(camera, target)
    # Warm up (first estimates, caches), then measure.
    for t, i, u, v in rows[:2000]:
        tracker.push(t, int(i), u, v)
    gc.collect()
    counts = [sys.getrefcount(x) for x in (tracker, camera, target, None)]
    objects = len(gc.get_objects())
    tracemalloc.start()
    before = tracemalloc.take_snapshot()
    estimates = 0
    last = None
    for t, i, u, v in rows[2000:102_000]:
        e = tracker.push(t, int(i), u, v)
        if e is not None:
            estimates += 1
            last = e
            e.position_m, e.covariance, e.status  # the getters too
    del e
    gc.collect()
    after = tracemalloc.take_snapshot()
    tracemalloc.stop()
    assert estimates >= 9_000 and last is not None
    del last
    grown = sum(s.size_diff for s in after.compare_to(before, "filename") if s.size_diff > 0)
    assert grown < 64 * 1024, f"the Python heap grew by {grown} bytes"
    assert [sys.getrefcount(x) for x in (tracker, camera, target, None)][:3] == counts[:3]
    assert len(gc.get_objects()) - objects < 100
    assert tracker.measurements == 102_000


def test_no_leak_on_refused_pushes_and_repeated_calls() -> None:
    sim = roitrack.simulate("static", seed=1)
    camera, target, rows = sim["camera"], sim["target"], sim["measurements"]
    tracker = roitrack.Tracker(camera, target)
    gc.collect()
    counts = [sys.getrefcount(x) for x in (tracker, camera, target, rows)]
    for _ in range(10_000):
        try:
            tracker.push(1.0, 99, 1.0, 1.0)
        except roitrack.RoitrackError:
            pass
    for _ in range(5):
        res = roitrack.track(camera, target, rows)
        roitrack.evaluate(sim, res)
    del res
    gc.collect()
    assert [sys.getrefcount(x) for x in (tracker, camera, target, rows)] == counts


def test_track_releases_the_gil() -> None:
    sim = roitrack.simulate("orthoglide", seed=1, rate_hz=16000.0)
    started, done = threading.Event(), threading.Event()

    def work() -> None:
        started.set()
        roitrack.track(sim["camera"], sim["target"], sim["measurements"])
        done.set()

    thread = threading.Thread(target=work)
    thread.start()
    started.wait()
    spins = 0
    while not done.is_set():
        spins += 1
    thread.join()
    # With the GIL held by track(), this loop could not run while it tracks (about 0.1 s of work).
    assert spins > 1000, spins
