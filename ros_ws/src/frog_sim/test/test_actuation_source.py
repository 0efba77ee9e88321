"""Where the eq. 9 coefficients come from: the shipped fit, refits, mismatches."""
import csv
import json

import numpy as np
import pytest

from frog_sim.core import actuation
from frog_sim.core.actuation import (DATA_FILE_NAME, ActuationLibrary, CurvatureProfile, StaleFitWarning,
                                     file_sha256, package_fit_path)



def _true_coefficients(switch=0.25):
    """A known eq. 9 profile (C1a, C2a, C3a, C4a, C1d, C2d, C3d, C4d), continuous at the switch."""
    act = -80.0 / (1.0 + np.exp(-60.0 * (switch - 0.08))) + 122.0
    c4d = act - 78.0 / (1.0 + np.exp(-12.0 * (switch - 0.55)))
    return (-80.0, 60.0, 0.08, 122.0, 78.0, 12.0, 0.55, float(c4d))


TRUE_COEF = _true_coefficients()


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("FROG_SIM_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("FROG_SIM_REFIT", raising=False)


def _synthetic_csv(path, egain=10.0, frequency=1.0):
    prof = CurvatureProfile(egain, frequency, TRUE_COEF, 0.25, 1.0 / frequency, 0.0)
    t = np.arange(0.0, 1.0 / frequency, 1.0 / 240.0)
    kappa = prof.curvature(t)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["egain_vol_pct", "frequency_hz", "t_s", "curvature_per_m"])
        for a, b in zip(t, kappa):
            w.writerow([egain, frequency, f"{a:.6f}", f"{b:.6f}"])
    return prof


def test_shipped_fit_is_used_without_measurements(tmp_path, monkeypatch):
    monkeypatch.setenv("FROG_DATA_DIR", str(tmp_path / "nothing_here"))
    lib = ActuationLibrary.load()
    assert lib.source["verified"] is False
    assert lib.source["loaded_from"] == str(package_fit_path())
    assert len(lib.profiles) == 48                  # the data README: 48 (EGaIn, frequency) pairs
    assert len(lib.source["data_sha256"]) == 64
    for p in lib.profiles.values():
        assert len(p.coefficients) == 8 and np.isfinite(p.rms_error) and 0 < p.switch_time < p.cycle_time
    with pytest.raises(FileNotFoundError, match=DATA_FILE_NAME):
        ActuationLibrary.load(refit=True)


def test_shipped_fit_matches_a_refit_of_the_measurements(measured_file):
    """The shipped file is what `frog-sim fit --write-package-data` makes from today's data."""
    path = measured_file(DATA_FILE_NAME)
    shipped = json.loads(package_fit_path().read_text())
    assert shipped["source"]["data_sha256"] == file_sha256(path)
    lib = ActuationLibrary.load()
    assert lib.source["verified"] is True
    fresh = ActuationLibrary.fit_file(path, use_cache=False)
    assert set(fresh.profiles) == set(lib.profiles)
    t = np.linspace(0.0, 0.999, 200)
    for key, prof in fresh.profiles.items():
        assert np.allclose(lib.profiles[key].curvature(t * prof.cycle_time),
                           prof.curvature(t * prof.cycle_time), atol=1e-6), key


def test_other_data_are_refitted_with_a_warning(tmp_path, monkeypatch):
    """A data hash that differs from the shipped fit's is never ignored silently."""
    truth = _synthetic_csv(tmp_path / DATA_FILE_NAME)
    monkeypatch.setenv("FROG_DATA_DIR", str(tmp_path))
    with pytest.warns(StaleFitWarning, match="differs from the data of the shipped"):
        lib = ActuationLibrary.load()
    assert list(lib.profiles) == [(10.0, 1.0)]
    assert lib.source["data_sha256"] == file_sha256(tmp_path / DATA_FILE_NAME)
    t = np.linspace(0.0, 0.99, 300)
    fitted = lib.profile(10, 1.0)
    assert np.max(np.abs(fitted.curvature(t) - truth.curvature(t))) < 1.0     # [1/m] of a 80 1/m stroke
    assert fitted.rms_error < 0.05
    # second load: from the cache, same numbers
    with pytest.warns(StaleFitWarning):
        again = ActuationLibrary.load()
    assert again.source["loaded_from"].startswith(str(tmp_path / "cache"))
    assert again.profile(10, 1.0).coefficients == pytest.approx(fitted.coefficients)


def test_refit_on_request_and_written_file_round_trips(tmp_path, monkeypatch):
    _synthetic_csv(tmp_path / DATA_FILE_NAME)
    monkeypatch.setenv("FROG_DATA_DIR", str(tmp_path))
    monkeypatch.setenv("FROG_SIM_REFIT", "1")
    lib = ActuationLibrary.load()
    out = lib.write_json(tmp_path / "pkg" / "actuation_fit.json")
    obj = json.loads(out.read_text())
    assert "loaded_from" not in obj["source"] and obj["source"]["data_sha256"] == lib.source["data_sha256"]
    # a package whose shipped file is this one loads it when the same data are at hand
    monkeypatch.delenv("FROG_SIM_REFIT")
    monkeypatch.setattr(actuation, "package_fit_path", lambda: out)
    shipped = ActuationLibrary.load()
    assert shipped.source["loaded_from"] == str(out) and shipped.source["verified"] is True
    assert shipped.profile(10, 1.0).coefficients == pytest.approx(lib.profile(10, 1.0).coefficients)


def test_missing_shipped_fit_and_no_data_names_both(tmp_path, monkeypatch):
    monkeypatch.setenv("FROG_DATA_DIR", str(tmp_path))
    monkeypatch.setattr(actuation, "package_fit_path", lambda: tmp_path / "gone.json")
    with pytest.raises(FileNotFoundError, match=r"gone.json is missing and limb_curvature_profiles.csv"):
        ActuationLibrary.load()
