"""`antarium.core.handover`: objects handed between processes through a shared mapping, their arrays not copied."""

import mmap
import os
import pickle
import subprocess
import sys

import numpy as np
import pytest

from antarium.core import handover


def _owner(array):
    while isinstance(array, np.ndarray) and array.base is not None:
        array = array.base
    return array.obj if isinstance(array, memoryview) else array


def test_arrays_come_back_equal_writable_and_as_views_of_one_mapping(tmp_path):
    obj = {"v": np.arange(12, dtype=np.float32).reshape(4, 3), "i": np.arange(5, dtype=np.uint32),
           "f": np.asfortranarray(np.ones((3, 2))), "name": "bush", "n": 3}
    h = handover.dump(obj, folder=str(tmp_path))
    assert os.path.exists(h.path) and h.nbytes == 48 + 20 + 48 and len(h.pickle) < 1000
    assert all(offset % handover.ALIGN == 0 for offset, _ in h.spans)
    back = handover.load(h)
    assert not os.path.exists(h.path)  # the name goes at once; the mapping stays
    for key in ("v", "i", "f"):
        np.testing.assert_array_equal(back[key], obj[key])
        assert back[key].dtype == obj[key].dtype and back[key].flags.writeable
        assert isinstance(_owner(back[key]), mmap.mmap)
    assert back["f"].flags.f_contiguous and back["name"] == "bush" and back["n"] == 3
    handover.discard(h)  # safe once loaded


def test_an_object_without_buffers_needs_no_file():
    h = handover.dump({"a": 1, "b": [2.0, "x"]})
    assert h.path == "" and h.spans == ()
    assert handover.load(h) == {"a": 1, "b": [2.0, "x"]}


def test_a_handover_never_loaded_is_removed_by_discard(tmp_path):
    h = handover.dump(np.zeros(100), folder=str(tmp_path))
    handover.discard(h)
    handover.discard(h)
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(FileNotFoundError):
        handover.load(h)


def test_arrays_dumped_by_another_process_load_here(tmp_path):
    """What the scene's process does: dump there; here only the small `Handover` arrives."""
    code = ("import sys, pickle, numpy as np; from antarium.core import handover; "
            "data = np.random.default_rng(0).random((1000, 9)).astype(np.float32); "
            f"sys.stdout.buffer.write(pickle.dumps(handover.dump(data, folder={str(tmp_path)!r})))")
    sent = subprocess.run([sys.executable, "-c", code], capture_output=True, check=True).stdout
    assert len(sent) < 1000
    back = handover.load(pickle.loads(sent))
    np.testing.assert_array_equal(back, np.random.default_rng(0).random((1000, 9)).astype(np.float32))
    assert list(tmp_path.iterdir()) == []
