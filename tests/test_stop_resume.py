"""A run stopped by a signal and resumed by the same call gives the uninterrupted run's
answer bit for bit.

The stops are chosen at random but reproducibly (a seeded generator): in the hydro stage
in the middle of a step (the signal arrives inside a directional sweep; the stage finishes
the step, writes its checkpoint and stops), twice in a row (the second signal stops at
once; the resume starts from the last periodic checkpoint), and in the N-body stage after a
chunk.  Files are compared dataset by dataset, summary.json entry by entry (wall times,
dates and paths aside).
"""

from __future__ import annotations

import json
import shutil
import signal
from pathlib import Path

import h5py
import numpy as np
import pytest

from impactpipe.hydro import solver
from impactpipe.pipeline import load_config, run
from impactpipe.pipeline import stages as orchestrator

QUICKSTART = Path(__file__).resolve().parent.parent / "configs" / "quickstart.yaml"
#: The quickstart cut short so that tens of stops stay cheap; checkpoints only when stopped.
OVERRIDES = {"hydro.end_time": 0.12, "hydro.checkpoint_wall_seconds": 1.0e6, "nbody.stop.min_dynamical_times": 5}
RNG_SEED = 20261124
HYDRO_STOPS = 10
NBODY_STOPS = 4
#: summary.json entries that legitimately differ between two runs of the same config.
VOLATILE = {"wall_seconds", "run_dir", "started", "finished"}


#: Variants of the mesh and the physics the stops are also taken in (a few stops each).
VARIANTS = {
    "uniform": {"hydro.max_levels": 1},
    "strength": {"materials.basalt.strength": {"model": "geo", "preset": "weak"}},
}
VARIANT_STOPS = 2


def config(variant: str | None = None):
    return load_config(QUICKSTART, overrides={**OVERRIDES, **VARIANTS.get(variant, {})})


def h5_datasets(path: Path) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, obj: out.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
    return out


def assert_same_files(run_dir: Path, reference: Path, names: tuple[str, ...]) -> None:
    for name in names:
        got, want = h5_datasets(run_dir / name), h5_datasets(reference / name)
        assert sorted(got) == sorted(want), name
        for key in want:
            assert np.array_equal(got[key], want[key], equal_nan=want[key].dtype.kind == "f"), f"{name}:{key}"


def stable(entries):
    if isinstance(entries, dict):
        return {k: stable(v) for k, v in entries.items() if k not in VOLATILE}
    return entries


def assert_same_summary(run_dir: Path, reference: Path, keys=None) -> None:
    got = stable(json.loads((run_dir / "summary.json").read_text()))
    want = stable(json.loads((reference / "summary.json").read_text()))
    keys = keys or sorted(set(want) - {"stages"})
    for key in keys:
        assert got.get(key) == want[key], key


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("uninterrupted")
    run(config(), out, show_progress=False)
    with h5py.File(out / "hydro.h5", "r") as f:
        steps = int(f.attrs["steps"])
    return out, steps


def sweeps_signalling(calls: list[int], signum=signal.SIGINT):
    """A stand-in for the sweep kernel that raises ``signum`` before its n-th call for each n in
    ``calls`` (counted from 1), then sweeps as usual."""
    real = solver.sweep
    count = [0]

    def sweep(*args):
        count[0] += 1
        if count[0] in calls:
            signal.raise_signal(signum)
        return real(*args)

    return sweep


def hydro_stops():
    rng = np.random.default_rng(RNG_SEED)
    return rng.random(HYDRO_STOPS)


@pytest.mark.parametrize("where", hydro_stops(), ids=lambda w: f"at{w:.3f}")
def test_a_hydro_stop_mid_step_resumes_to_the_same_answer(where, reference, tmp_path, monkeypatch):
    ref, steps = reference
    call = 1 + int(where * (2 * steps - 1))  # two sweeps per step in 2d
    monkeypatch.setattr(solver, "sweep", sweeps_signalling([call]))
    with pytest.raises(orchestrator.StageInterrupted, match="SIGINT"):
        run(config(), tmp_path, stages=["hydro"], show_progress=False)
    assert (tmp_path / "hydro.checkpoint.h5").is_file()
    monkeypatch.undo()
    run(config(), tmp_path, stages=["hydro"], show_progress=False)
    assert_same_files(tmp_path, ref, ("hydro.h5",))
    assert_same_summary(tmp_path, ref, ["hydro_budget", "tracers"])


@pytest.fixture(scope="module", params=sorted(VARIANTS))
def variant_reference(request, tmp_path_factory):
    out = tmp_path_factory.mktemp(request.param)
    run(config(request.param), out, stages=["hydro"], show_progress=False)
    with h5py.File(out / "hydro.h5", "r") as f:
        steps = int(f.attrs["steps"])
    return request.param, out, steps


def test_hydro_stops_on_a_uniform_mesh_and_with_strength(variant_reference, tmp_path, monkeypatch):
    variant, ref, steps = variant_reference
    rng = np.random.default_rng(RNG_SEED + 2)
    for k, where in enumerate(rng.random(VARIANT_STOPS)):
        run_dir = tmp_path / f"stop{k}"
        monkeypatch.setattr(solver, "sweep", sweeps_signalling([1 + int(where * (2 * steps - 1))]))
        with pytest.raises(orchestrator.StageInterrupted):
            run(config(variant), run_dir, stages=["hydro"], show_progress=False)
        monkeypatch.undo()
        run(config(variant), run_dir, stages=["hydro"], show_progress=False)
        assert_same_files(run_dir, ref, ("hydro.h5",))


def test_two_signals_stop_at_once_and_the_resume_is_still_exact(reference, tmp_path, monkeypatch):
    ref, steps = reference
    monkeypatch.setattr(solver, "sweep", sweeps_signalling([steps, steps + 1], signal.SIGTERM))
    with pytest.raises(orchestrator.StageInterrupted, match="SIGTERM"):
        run(config(), tmp_path, show_progress=False)
    monkeypatch.undo()
    run(config(), tmp_path, show_progress=False)
    assert_same_files(tmp_path, ref, ("hydro.h5", "handoff.h5", "nbody.h5", "analysis.h5"))
    assert_same_summary(tmp_path, ref)


def signalling_progress(stage_name: str, at_call: int | None, counter: list[int]):
    """A stand-in for StageContext.progress that counts the reporter's calls in stage
    ``stage_name`` and raises SIGTERM at call ``at_call``."""
    real_progress = orchestrator.StageContext.progress

    def progress(self, stage, total):
        reporter = real_progress(self, stage, total)

        def report(t):
            if stage == stage_name:
                counter[0] += 1
                if counter[0] == at_call:
                    signal.raise_signal(signal.SIGTERM)
            reporter(t)

        report.close = reporter.close
        return report

    return progress


@pytest.fixture(scope="module")
def handed_off(reference, tmp_path_factory):
    """A run directory with the reference's hydro and hand-off stages done, and the number
    of chunks (progress reports) of the N-body stage."""
    out = tmp_path_factory.mktemp("handed_off")
    run(config(), out, stages=["hydro", "handoff"], show_progress=False)
    counted = tmp_path_factory.mktemp("counted")
    shutil.copytree(out, counted, dirs_exist_ok=True)
    chunks = [0]
    patch = pytest.MonkeyPatch()
    patch.setattr(orchestrator.StageContext, "progress", signalling_progress("nbody", None, chunks))
    try:
        run(config(), counted, stages=["nbody"], show_progress=False)
    finally:
        patch.undo()
    return out, chunks[0]


@pytest.mark.parametrize("where", np.random.default_rng(RNG_SEED + 1).random(NBODY_STOPS), ids=lambda w: f"at{w:.3f}")
def test_an_nbody_stop_after_a_chunk_resumes_to_the_same_answer(where, reference, handed_off, tmp_path,
                                                                  monkeypatch):
    ref, _ = reference
    base, chunks = handed_off
    assert chunks > 1
    run_dir = tmp_path / "run"
    shutil.copytree(base, run_dir)
    at_call = 1 + int(where * (chunks - 1))
    monkeypatch.setattr(orchestrator.StageContext, "progress", signalling_progress("nbody", at_call, [0]))
    with pytest.raises(orchestrator.StageInterrupted, match="SIGTERM"):
        run(config(), run_dir, show_progress=False)
    monkeypatch.undo()
    run(config(), run_dir, show_progress=False)
    assert_same_files(run_dir, ref, ("nbody.h5", "analysis.h5"))
    assert_same_summary(run_dir, ref)
