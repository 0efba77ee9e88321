"""The library reader accepts a format-1 file and rejects broken ones with a message naming the problem."""

import json

import numpy as np
import pytest
from frog_common.motion_library_file import LibraryFormatError, load_motion_library


@pytest.fixture
def arrays(synthetic):
    return synthetic.library_arrays(n_states=12, horizon=2.0, sample_interval=0.1)


def test_valid_file_loads_with_its_values(tmp_path, arrays):
    path = _write(tmp_path / "lib.npz", arrays)
    lib = load_motion_library(path)
    assert list(lib.primitive_names) == list("ABCDEFGHI")
    assert lib.transitions.shape == (9, 12, 21, 6)
    assert lib.sample_interval == pytest.approx(0.1)
    assert lib.horizon == pytest.approx(2.0)
    np.testing.assert_array_equal(lib.initial_states, arrays["initial_states"])
    assert lib.metadata["code_version"] == "test synthetic"


@pytest.mark.parametrize("period, index", [(0.1, 1), (1.5, 15), (2.0, 20), (0.7, 7)])
def test_period_selects_the_sample_at_that_time(tmp_path, arrays, period, index):
    lib = load_motion_library(_write(tmp_path / "lib.npz", arrays))
    assert lib.time_index(period) == index
    np.testing.assert_array_equal(lib.transitions_at(period), arrays["transitions"][:, :, index, :].astype(float))


@pytest.mark.parametrize("period, words", [(2.1, "beyond the library horizon 2.0"), (0.0, "positive"),
                                           (-1.0, "positive"), (float("nan"), "positive")])
def test_bad_periods_are_rejected(tmp_path, arrays, period, words):
    lib = load_motion_library(_write(tmp_path / "lib.npz", arrays))
    with pytest.raises(ValueError, match=words):
        lib.transitions_at(period)


@pytest.mark.parametrize("period", [0.15, 1.43, 1.97])
def test_off_grid_periods_interpolate_close_to_the_model(tmp_path, arrays, synthetic, period):
    """Between samples, transitions match the kinematic model integrated to that very time."""
    lib = load_motion_library(_write(tmp_path / "lib.npz", arrays))
    with pytest.raises(ValueError, match="not a multiple"):
        lib.time_index(period)
    exact = synthetic.kinematic_transitions(arrays["initial_states"], np.array([0.0, period]), substeps=400)[:, :, 1]
    got = lib.transitions_at(period)
    scale = np.abs(exact).max(axis=(0, 1))
    assert np.all(np.abs(got - exact).max(axis=(0, 1)) <= 0.01 * scale + 1e-6)


def _write(path, arrays):
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)
    return path


def _broken(arrays, key, value):
    out = dict(arrays)
    if value is None:
        del out[key]
    else:
        out[key] = value
    return out


def _nan_in_converged_row(a):
    t = a["transitions"].copy()
    t[4, 3, 5, 1] = np.nan
    return t


@pytest.mark.parametrize("key, value, words", [
    ("transitions", None, r"lacks key\(s\) \['transitions'\]"),
    ("format", np.array("something-else"), "format is 'something-else'; expected 'frog-motion-library'"),
    ("format_version", np.array(2), "format_version is 2"),
    ("initial_states", np.zeros((12, 2)), r"initial_states has shape \(12, 2\)"),
    ("primitive_bits", np.array(["1100"] * 8), r"primitive_bits has shape \(8,\)"),
    ("converged", np.ones((9, 11), dtype=bool), r"converged has shape \(9, 11\)"),
    ("state_names", np.array(["u", "v", "w"]), "state_names"),
    ("metadata", np.array("{not json"), "metadata is not valid JSON"),
    ("metadata", np.array(json.dumps([1, 2])), "metadata is a JSON list"),
])
def test_inconsistent_contents_are_rejected(tmp_path, arrays, key, value, words):
    path = _write(tmp_path / "lib.npz", _broken(arrays, key, value))
    with pytest.raises(LibraryFormatError, match=words):
        load_motion_library(path)


def test_transitions_of_another_shape_are_rejected(tmp_path, arrays):
    path = _write(tmp_path / "lib.npz", _broken(arrays, "transitions", arrays["transitions"][:, :, :-1]))
    with pytest.raises(LibraryFormatError, match=r"transitions has shape \(9, 12, 20, 6\); expected \(9, 12, 21, 6\)"):
        load_motion_library(path)


def test_non_uniform_times_are_rejected(tmp_path, arrays):
    times = arrays["times"].copy()
    times[5] += 0.03
    with pytest.raises(LibraryFormatError, match="not uniform"):
        load_motion_library(_write(tmp_path / "lib.npz", _broken(arrays, "times", times)))


def test_non_increasing_times_are_rejected(tmp_path, arrays):
    times = arrays["times"].copy()
    times[6] = times[5]
    with pytest.raises(LibraryFormatError, match="not increasing at index 6"):
        load_motion_library(_write(tmp_path / "lib.npz", _broken(arrays, "times", times)))


def test_nan_in_a_converged_row_is_rejected_but_allowed_in_a_failed_one(tmp_path, arrays):
    bad = _broken(arrays, "transitions", _nan_in_converged_row(arrays))
    with pytest.raises(LibraryFormatError, match=r"transitions\[4, 3\] \(primitive E, initial state 3\)"):
        load_motion_library(_write(tmp_path / "bad.npz", bad))
    conv = arrays["converged"].copy()
    conv[4, 3] = False
    ok = _broken(bad, "converged", conv)
    lib = load_motion_library(_write(tmp_path / "ok.npz", ok))
    assert not lib.converged[4, 3]


def test_truncated_file_is_rejected(tmp_path, arrays):
    whole = (_write(tmp_path / "lib.npz", arrays)).read_bytes()
    for cut in (len(whole) // 2, len(whole) - 30, 100):
        path = tmp_path / f"cut{cut}.npz"
        path.write_bytes(whole[:cut])
        with pytest.raises(LibraryFormatError, match="not a readable .npz"):
            load_motion_library(path)


def test_foreign_files_are_rejected(tmp_path):
    text = tmp_path / "notes.npz"
    text.write_text("x,y\n0,0\n")
    with pytest.raises(LibraryFormatError, match="not a readable .npz"):
        load_motion_library(text)
    npy = tmp_path / "array.npy"
    np.save(npy, np.zeros(3))
    with pytest.raises(LibraryFormatError, match="single .npy array"):
        load_motion_library(npy)
    other = tmp_path / "other.npz"
    np.savez(other, weights=np.zeros(3))
    with pytest.raises(LibraryFormatError, match="lacks key"):
        load_motion_library(other)


def test_pickled_contents_are_rejected(tmp_path, arrays):
    path = _write(tmp_path / "lib.npz", _broken(arrays, "metadata", np.array({"a": 1}, dtype=object)))
    with pytest.raises(LibraryFormatError, match="not a readable .npz"):
        load_motion_library(path)


def test_missing_file_names_the_path(tmp_path):
    with pytest.raises(FileNotFoundError, match="nowhere.npz does not exist"):
        load_motion_library(tmp_path / "nowhere.npz")
