"""`process` releases the GIL: another Python thread runs while a frame is
processed, and two sensors in two threads give the results they give alone.

No wall-clock bound is asserted (the machine may be loaded): the check is
whether the main thread ran Python code at all while the worker was inside
`process`. With the switch interval set far beyond the test's length, a
thread that holds the GIL is never made to hand it over; the main thread can
then only run while the worker is inside a call that released it.
"""

from __future__ import annotations

import sys
import threading
import time

import dexitac

# The exact density (every pixel) makes one frame take tens of ms.
SLOW = {"density": {"mode": "exact"}}


def test_main_thread_runs_while_a_frame_is_processed(nominal):
    sensor = dexitac.Sensor.from_rest(nominal.rest, config=SLOW)
    frames = [f for f in nominal.frames if sensor.process(f).contact is not None][:4] * 2
    assert frames, "needs frames with a contact (the density stage runs)"
    state = {"inside": False, "done": False}
    seen_inside = 0

    def worker():
        for f in frames:
            state["inside"] = True
            sensor.process(f)
            state["inside"] = False
        state["done"] = True

    old = sys.getswitchinterval()
    sys.setswitchinterval(1000.0)
    try:
        t = threading.Thread(target=worker)
        t.start()
        while not state["done"]:
            if state["inside"]:
                seen_inside += 1
            # A short blocking call: the GIL is free meanwhile, so the
            # worker takes it back when its call returns (it never waits
            # for the switch interval).
            time.sleep(0.0005)
        t.join()
    finally:
        sys.setswitchinterval(old)
    # GIL held through `process`: the main thread cannot run between the
    # worker setting `inside` and the call returning, so it sees it 0 times.
    assert seen_inside > 10, f"main thread ran {seen_inside} times while the worker was in process()"


def test_two_sensors_in_two_threads_give_their_own_results(nominal, large):
    jobs = [(dexitac.Sensor.from_rest(s.rest), s.frames * 3) for s in (nominal, large)]
    alone = [[sensor.process(f) for f in frames] for sensor, frames in jobs]
    together: list[list] = [[], []]

    def run(k):
        sensor, frames = jobs[k]
        together[k] = [sensor.process(f) for f in frames]

    threads = [threading.Thread(target=run, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for a_list, b_list in zip(alone, together):
        assert len(a_list) == len(b_list)
        for a, b in zip(a_list, b_list):
            assert (a.contact and a.contact.centre_px) == (b.contact and b.contact.centre_px)
            assert a.markers_px.tobytes() == b.markers_px.tobytes()


def test_one_sensor_shared_by_threads(nominal):
    sensor = dexitac.Sensor.from_rest(nominal.rest)
    want = [sensor.process(f).markers_px.tobytes() for f in nominal.frames]
    got: dict[int, list[bytes]] = {}

    def run(k):
        got[k] = [sensor.process(f).markers_px.tobytes() for f in nominal.frames]

    threads = [threading.Thread(target=run, args=(k,)) for k in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert all(v == want for v in got.values())
