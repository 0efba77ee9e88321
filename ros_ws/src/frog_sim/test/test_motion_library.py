"""Motion-primitive library: batch determinism, resume, Dask, file validation, physics checks."""

import json
import subprocess
import sys
import time

import numpy as np
import pytest

from frog_common.motion_library_file import load_motion_library
from frog_sim.core.batch import BatchError, run_chunked
from frog_sim.core.motion_library import LibrarySpec, generate_library, simulate_transitions
from frog_sim.core.simulation import FrogSimulation

SMALL = dict(n_states=7, horizon=0.2, sample_interval=0.05, seed=3)   # 4 mirror pairs, last cut
VOLATILE = ("created", "generation_wall_time_s")
FIELDS = ("primitive_names", "primitive_bits", "initial_states", "times", "transitions", "converged",
          "metadata")


def load_library(path) -> dict:
    """The file through the planner's reader (frog_common), as a dict of its fields."""
    lib = load_motion_library(path)
    return {k: getattr(lib, k) for k in FIELDS}


def _same_library(a, b):
    la, lb = load_library(a), load_library(b)
    for key in la:
        if key == "metadata":
            ma = {k: v for k, v in la[key].items() if k not in VOLATILE}
            mb = {k: v for k, v in lb[key].items() if k not in VOLATILE}
            assert ma == mb
        else:
            assert la[key].dtype == lb[key].dtype and np.array_equal(la[key], lb[key]), key


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The small library computed in this process, one chunk at a time."""
    path = tmp_path_factory.mktemp("ref") / "ref.npz"
    return generate_library(LibrarySpec(**SMALL), path, workers=1, chunk_size=1, progress=False)


def test_file_contents_follow_the_contract(reference):
    lib = load_library(reference)
    assert lib["transitions"].shape == (9, 7, 5, 6) and lib["transitions"].dtype == np.float32
    assert list(lib["primitive_names"]) == list("ABCDEFGHI")
    assert np.allclose(lib["times"], [0, 0.05, 0.1, 0.15, 0.2])
    meta = lib["metadata"]
    assert meta["units"]["transitions"] == ["m", "m", "rad", "m/s", "m/s", "rad/s"]
    assert meta["sampling"]["seed"] == 3 and len(meta["robot_hash"]) == 64
    s = lib["initial_states"]
    assert np.all((s[:, 0] >= 0) & (s[:, 0] <= 0.04) & (np.abs(s[:, 1]) <= 0.03)
                  & (np.abs(s[:, 2]) <= np.deg2rad(30)))


def test_states_at_t0_reproduce_sampled_velocities(reference):
    """eq. 13 (rigid velocity field) then eq. 10-12 (rigid-body state) is a round trip."""
    lib = load_library(reference)
    t0 = lib["transitions"][:, :, 0, :]
    assert np.abs(t0[..., :3]).max() < 1e-9                      # start pose is the origin
    err = np.abs(t0[..., 3:] - lib["initial_states"][None]).max()
    assert err < 1e-6, f"round-trip error {err:.2e} (float32 storage ~1e-9 m/s)"


@pytest.mark.system
def test_process_pool_gives_identical_file(reference, tmp_path):
    out = generate_library(LibrarySpec(**SMALL), tmp_path / "pool.npz", workers=2,
                           chunk_size=1, progress=False)
    _same_library(reference, out)


@pytest.mark.system
def test_dask_local_cluster_gives_identical_file(reference, tmp_path):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        out = generate_library(LibrarySpec(**SMALL), tmp_path / "dask.npz",
                               scheduler=cluster.scheduler_address, chunk_size=1, progress=False)
    _same_library(reference, out)


@pytest.mark.system
def test_resume_after_killed_run_gives_identical_file(reference, tmp_path):
    out = tmp_path / "resumed.npz"
    code = (f"from frog_sim.core.motion_library import LibrarySpec, generate_library\n"
            f"if __name__ == '__main__':\n"
            f"    generate_library(LibrarySpec(**{SMALL!r}), {str(out)!r}, workers=1, chunk_size=1,"
            f" progress=False)\n")
    proc = subprocess.Popen([sys.executable, "-c", code])
    chunks = tmp_path / "resumed.npz.chunks"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and len(list(chunks.glob("chunk_*.npz"))) < 2:
        time.sleep(0.02)
    proc.kill()
    proc.wait()
    done_before = sorted(p.name for p in chunks.glob("chunk_*.npz"))
    assert 2 <= len(done_before) < 4 and not out.exists(), done_before   # 4 chunks (pairs)
    # a torn temporary file from the kill must not be mistaken for a chunk
    (chunks / "chunk_000003.npz.partial.tmp").write_bytes(b"PK\x03\x04garbage")
    generate_library(LibrarySpec(**SMALL), out, workers=1, chunk_size=1, progress=False)
    _same_library(reference, out)


def test_work_folder_of_another_job_is_refused(tmp_path):
    generate_library(LibrarySpec(**SMALL), tmp_path / "a.npz", work_dir=tmp_path / "w",
                     workers=1, chunk_size=2, progress=False)
    other = dict(SMALL, seed=4)
    with pytest.raises(BatchError, match="holds chunks of another job"):
        generate_library(LibrarySpec(**other), tmp_path / "b.npz", work_dir=tmp_path / "w",
                         workers=1, chunk_size=2, progress=False)


def test_corrupt_chunk_is_recomputed(tmp_path):
    lib = generate_library(LibrarySpec(**SMALL), tmp_path / "a.npz", workers=1, chunk_size=2,
                           progress=False)
    chunk = tmp_path / "a.npz.chunks" / "chunk_000001.npz"
    chunk.write_bytes(chunk.read_bytes()[:100])
    again = generate_library(LibrarySpec(**SMALL), tmp_path / "b.npz",
                             work_dir=tmp_path / "a.npz.chunks", workers=1, chunk_size=2,
                             progress=False)
    _same_library(lib, again)


def test_mirror_pairs_match_direct_simulation(reference, sim):
    """Rows 2i+1 are reflections of rows 2i; check them against simulating the state."""
    lib = load_library(reference)
    states = lib["initial_states"]
    assert np.allclose(states[1::2], states[0:-1:2] * [1, -1, -1])
    direct, ok = simulate_transitions(sim, states[3], 0.2, 0.05)
    stored = lib["transitions"][:, 3]
    scale = np.abs(direct).max(axis=(0, 1))
    err = np.abs(stored - direct).max(axis=(0, 1)) / np.maximum(scale, 1e-12)
    assert ok.all() and err.max() < 1e-5, f"relative error per column {err}"
    meta = lib["metadata"]["sampling"]
    assert meta["mirror_pairs"] and meta["simulated_transitions"] == 9 * 4


def test_without_mirror_every_state_is_simulated(tmp_path, sim):
    spec = LibrarySpec(n_states=3, horizon=0.1, sample_interval=0.05, seed=5, mirror=False)
    lib = load_library(generate_library(spec, tmp_path / "m.npz", workers=1, progress=False))
    states = lib["initial_states"]
    assert not np.allclose(states[1], states[0] * [1, -1, -1])
    direct, _ = simulate_transitions(sim, states[2], 0.1, 0.05)
    assert np.allclose(lib["transitions"][:, 2], direct, rtol=1e-5, atol=1e-9)
    assert lib["metadata"]["sampling"]["simulated_transitions"] == 27


@pytest.fixture(scope="module")
def sim():
    return FrogSimulation()


def test_no_action_from_rest_stays_at_rest(sim):
    out, ok = simulate_transitions(sim, (0.0, 0.0, 0.0), horizon=0.5, sample_interval=0.1,
                                   primitives=("I",))
    assert ok.all() and np.abs(out).max() < 1e-12


@pytest.mark.parametrize("left,right", [("G", "H"), ("E", "F")])
def test_mirrored_primitives_give_mirrored_transitions(sim, left, right):
    """Mirror about the body x axis: (x, y, heading) -> (x, -y, -heading); the initial
    state (forward, lateral, yaw rate) mirrors to (forward, -lateral, -yaw rate)."""
    state = np.array([0.02, 0.008, 0.2])
    mirrored = state * [1, -1, -1]
    a, _ = simulate_transitions(sim, state, 0.6, 0.1, primitives=(left,))
    b, _ = simulate_transitions(sim, mirrored, 0.6, 0.1, primitives=(right,))
    flip = np.array([1, -1, -1, 1, -1, -1])
    scale = np.abs(a).max(axis=(0, 1))
    err = np.abs(a - b * flip).max(axis=(0, 1)) / np.maximum(scale, 1e-12)
    assert err.max() < 1e-6, f"relative mirror error per column {err}"
    # and the primitive does something: G turns the other way than H
    assert abs(a[0, -1, 2] - b[0, -1, 2]) > 1e-4


def test_run_chunked_validates_task_output(tmp_path):
    with pytest.raises(BatchError, match="first axis"):
        run_chunked(_bad_task, {"x": 1}, 4, 2, tmp_path / "w", workers=1, progress=False)


def _bad_task(spec, start, stop):
    return {"a": np.zeros(stop - start + 1)}


def test_metadata_is_json(reference):
    with np.load(reference, allow_pickle=False) as z:
        meta = json.loads(str(z["metadata"]))
    assert meta["horizon_s"] == 0.2
