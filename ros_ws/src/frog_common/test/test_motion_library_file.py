"""The library writer: what it writes the reader reads back unchanged; what the reader would
refuse it refuses before touching the file. (The reader's refusals are tested in
frog_planner/test/test_library_file.py.)"""

import numpy as np
import pytest

from frog_common.motion_library_file import LibraryFormatError, load_motion_library, write_motion_library


def _arrays(n=4, t=5):
    rng = np.random.default_rng(0)
    return dict(initial_states=rng.normal(size=(n, 3)) * 0.01, times=np.arange(t) * 0.05,
                transitions=rng.normal(size=(9, n, t, 6)).astype(np.float32),
                converged=np.ones((9, n), bool), metadata={"code_version": "test"})


def test_round_trip(tmp_path):
    a = _arrays()
    lib = load_motion_library(write_motion_library(tmp_path / "lib.npz", **a))
    assert tuple(lib.primitive_names) == tuple("ABCDEFGHI")
    assert list(lib.primitive_bits) == ["1100", "1111", "0111", "1011", "0110", "1001", "0100", "1000", "0000"]
    np.testing.assert_array_equal(lib.transitions, a["transitions"])
    np.testing.assert_array_equal(lib.initial_states, a["initial_states"])
    np.testing.assert_allclose(lib.times, a["times"])
    assert lib.metadata == {"code_version": "test"}


@pytest.mark.parametrize("spoil, words", [
    (lambda a: a["transitions"].__setitem__((2, 1, 3, 0), np.nan), "marked converged"),
    (lambda a: a.update(times=np.array([0.0, 0.05, 0.2, 0.25, 0.3])), "not uniform"),
    (lambda a: a.update(initial_states=a["initial_states"][:2]), "transitions has shape"),
])
def test_writer_refuses_what_the_reader_would_and_leaves_no_file(tmp_path, spoil, words):
    a = _arrays()
    spoil(a)
    with pytest.raises(LibraryFormatError, match=words):
        write_motion_library(tmp_path / "lib.npz", **a)
    assert list(tmp_path.iterdir()) == []
