"""BufferedSource: samples pushed from another thread are handed over in order, bounded, drops reported."""

import threading

from antarium.locomotion import BallSample, BufferedSource


class _Fed(BufferedSource):
    pass


def _sample(i: int) -> BallSample:
    return BallSample(float(i), i, (0.0, 0.0, 0.0))


def test_read_hands_over_everything_since_the_last_read_in_order():
    src = _Fed(max_pending=1000)
    producer = threading.Thread(target=lambda: [src._push(_sample(i)) for i in range(500)])
    producer.start()
    producer.join()
    assert [s.seq for s in src.read()] == list(range(500))
    assert src.read() == []


def test_a_full_queue_drops_the_oldest_and_says_so():
    src = _Fed(max_pending=3)
    assert [src._push(_sample(i)) for i in range(5)] == [False, False, False, True, True]
    assert [s.seq for s in src.read()] == [2, 3, 4]
