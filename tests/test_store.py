"""Issue 20: a run streams its trajectory to disk (contactlab.store) — the same numbers as a run
held in memory, in flat memory however long it runs, kept with its status when the run stops
early, and read back a few samples at a time by render and export."""

import os
import signal
import tracemalloc

import numpy as np
import pytest
from conftest import ball_on_plane

from contactlab import InputError, ModelBuilder, SimulationDiverged, budget, render, simulate, store
from contactlab.export import write_mesh_sequence
from contactlab.interrupts import Interrupted
from contactlab.record import SERIES, sample_bytes
from contactlab.scene import load_scene


def _free_fall(count):
    """``count`` spheres falling side by side in empty space: no contact, many bytes a sample.
    2 m apart: each step's swept reach (h |v|, 0.6 m at 6 s of fall with h = 0.01 s) must not
    bridge the gaps, or neighbours become speculative contacts whose work grows as they fall (at
    0.3 m apart they did from about 1 s on, and a longer run's peak memory grew with them)."""
    b = ModelBuilder()
    b.add_material("m", friction=0.5, restitution=0.5)
    for i in range(count):
        b.add_body("sphere", radius=0.1, mass=1.0, position=(2.0 * i, 0.0, 10.0), material="m")
    return b.finalize()


@pytest.mark.parametrize("method", ["impulse", "penalty", "constraints"])
def test_a_streamed_run_is_bit_for_bit_the_run_held_in_memory(tmp_path, method):
    scene = load_scene("box_pyramid")
    arguments = (scene.model, method, scene.dt, 0.2, scene.method_options.get(method, {}), scene.integrator, 2)
    held = simulate(*arguments)
    streamed = simulate(*arguments, trajectory=tmp_path / "run.h5")
    file = store.open_trajectory(tmp_path / "run.h5")
    assert file.status == "complete" and file.record_every == 2
    assert set(file) == set(held.arrays)
    for name, values in held.arrays.items():
        np.testing.assert_array_equal(file[name], values, err_msg=name)
        assert file[name].dtype == values.dtype, name
    assert streamed.summary["samples"] == held.summary["samples"] == len(held.arrays["time"])
    for key in ("energy", "max_penetration", "final_penetration", "solver", "max_contacts"):
        assert streamed.summary[key] == held.summary[key], key
    assert os.listdir(tmp_path) == ["run.h5"]  # no temporary file left beside it


def test_a_file_reads_back_what_was_written_whole_or_a_few_samples_at_a_time(tmp_path):
    rng = np.random.default_rng(5)
    arrays = {
        "time": np.arange(40) * 0.01,
        "body_position": rng.normal(size=(40, 3, 3)),
        "contact_count": rng.integers(0, 9, size=40),
        "body_names": np.array(["a", "bé", "c"]),
        "particle_position": np.zeros((40, 0, 3)),
    }
    path = store.write(
        tmp_path / "t.h5",
        arrays,
        record_every=3,
        status="interrupted",
        series=("time", "body_position", "contact_count", "particle_position"),
    )
    file = store.open_trajectory(path)
    assert (file.status, file.record_every, len(file)) == ("interrupted", 3, 5)
    for name, values in arrays.items():
        np.testing.assert_array_equal(file[name], values)
        assert file[name].dtype.kind == values.dtype.kind
    for samples in (slice(5, 30, 7), [0, 3, 39], np.array([12])):
        np.testing.assert_array_equal(file.rows("body_position", samples), arrays["body_position"][samples])
    assert file.rows("particle_position", [1, 2]).shape == (2, 0, 3)
    assert file.shapes["body_position"] == (40, 3, 3)


def _peak_bytes(model, duration, trajectory):
    tracemalloc.start()
    try:
        simulate(model, "impulse", 0.01, duration, trajectory=trajectory)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_a_streamed_run_holds_flat_memory_however_long_it_runs(tmp_path):
    """300 spheres, 7.2 KB a sample: four times the samples (600 against 150, 4.3 MB against
    1.1 MB of trajectory) cost a run held in memory at least the extra trajectory, and a streamed
    run less than one chunk (store.CHUNK_BYTES) more."""
    model = _free_fall(300)
    simulate(model, "impulse", 0.01, 0.02)  # compiled and warm
    per_sample = sample_bytes(model)
    extra = (600 - 150) * per_sample
    held_growth = _peak_bytes(model, 6.0, None) - _peak_bytes(model, 1.5, None)
    streamed_growth = _peak_bytes(model, 6.0, tmp_path / "long.h5") - _peak_bytes(model, 1.5, tmp_path / "short.h5")
    assert held_growth >= extra
    assert streamed_growth < store.CHUNK_BYTES
    assert store.open_trajectory(tmp_path / "long.h5").shapes["body_position"] == (601, 300, 3)


def test_a_short_run_makes_a_small_file(tmp_path):
    """The chunks are no longer than the run: four samples of a ball take kilobytes, not the
    megabytes of full chunks."""
    simulate(ball_on_plane(), "impulse", 0.01, 0.03, trajectory=tmp_path / "ball.h5")
    assert os.path.getsize(tmp_path / "ball.h5") < 100_000


def test_a_diverged_run_keeps_its_samples_up_to_the_blow_up_marked_diverged(tmp_path):
    model = ball_on_plane(height=0.4, restitution=0.5, friction=0.0)
    with pytest.raises(SimulationDiverged) as stopped:
        simulate(
            model,
            "penalty",
            0.01,
            2.0,
            {"stiffness": 1e9, "implicit_springs": "never"},
            "explicit_euler",
            trajectory=tmp_path / "run.h5",
        )
    file = store.open_trajectory(tmp_path / "run.h5")
    assert file.status == "diverged"
    time = file["time"]
    assert time[-1] == pytest.approx(stopped.value.time) and len(time) == stopped.value.run.summary["samples"]
    np.testing.assert_array_equal(stopped.value.run.arrays["body_position"], file["body_position"])
    assert os.listdir(tmp_path) == ["run.h5"]


def test_an_interrupted_run_keeps_every_sample_it_made_marked_interrupted(tmp_path):
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    scene = load_scene("box_pyramid")
    from contactlab.methods import penalty

    real, calls = penalty.step, []

    def step(*arguments):
        calls.append(1)
        if len(calls) == 30:
            os.kill(os.getpid(), signal.SIGINT)
        return real(*arguments)

    penalty.step = step
    try:
        with pytest.raises(Interrupted) as interrupted:
            simulate(
                scene.model, "penalty", scene.dt, 1.0, trajectory=tmp_path / "run.h5", compiled_loop=False
            )  # the Python path, one call a step (not the loop)
    finally:
        penalty.step = real
        signal.signal(signal.SIGINT, previous)
    file = store.open_trajectory(tmp_path / "run.h5")
    assert file.status == "interrupted"
    assert len(file["time"]) == 31  # the initial state and the 30 steps made
    assert file["time"][-1] == pytest.approx(30 * scene.dt)
    assert interrupted.value.run.summary["samples"] == 31


def test_a_run_that_fails_otherwise_leaves_nothing(tmp_path, monkeypatch):
    from contactlab.methods import impulse

    real, calls = impulse.step, []

    def step(*arguments):
        calls.append(1)
        if len(calls) == 5:
            raise MemoryError("no memory left")
        return real(*arguments)

    monkeypatch.setattr(impulse, "step", step)
    with pytest.raises(MemoryError):
        simulate(ball_on_plane(), "impulse", 0.01, 0.5, compiled_loop=False, trajectory=tmp_path / "run.h5")
    assert os.listdir(tmp_path) == []


def test_a_trajectory_that_would_outgrow_its_disk_is_refused_before_the_run(tmp_path, monkeypatch):
    model = _free_fall(100)
    per_sample = sample_bytes(model)
    monkeypatch.setattr(budget, "_free_disk", lambda path: 100 * per_sample)
    with pytest.raises(InputError, match=r"record_every: the trajectory would take .* free on the disk") as refused:
        simulate(model, "impulse", 0.01, 2.0, trajectory=tmp_path / "run.h5")
    every = int(refused.value.message.split("record every ")[1].split(" steps")[0].replace(",", ""))
    assert budget.estimate(model, 200, every)["file"] <= 100 * per_sample
    assert os.listdir(tmp_path) == []
    simulate(model, "impulse", 0.01, 2.0, record_every=every, trajectory=tmp_path / "run.h5")
    assert len(store.open_trajectory(tmp_path / "run.h5")["time"]) <= 100


class _Reads(store.TrajectoryFile):
    """A trajectory file that notes what is read of it: names read whole, and rows read."""

    def __init__(self, path):
        super().__init__(path)
        self.whole, self.rows_read = [], {}

    def __getitem__(self, name):
        self.whole.append(name)
        return super().__getitem__(name)

    def rows(self, name, samples):
        chosen = np.arange(self.shapes[name][0])[samples]
        self.rows_read[name] = self.rows_read.get(name, 0) + len(chosen)
        return super().rows(name, samples)


def test_render_and_export_read_only_the_samples_they_use(tmp_path):
    """1000 samples (10 s at 100 per second): a 5 frame-per-second video reads its 51 frames of
    positions, an export every 100th sample its 11; time alone is read whole."""
    model = ball_on_plane(height=0.3, restitution=0.0)
    simulate(model, "impulse", 0.01, 10.0, trajectory=tmp_path / "run.h5")
    file = _Reads(tmp_path / "run.h5")
    render.render(file, tmp_path / "video", fps=5, formats="gif", width=64, height=48)
    assert [name for name in file.whole if name in SERIES] == ["time"]
    assert file.rows_read["body_position"] == 51
    file = _Reads(tmp_path / "run.h5")
    paths = write_mesh_sequence(file, tmp_path / "frames", every=100)
    assert len(paths) == 11 and file.rows_read["body_position"] == 11
    assert [name for name in file.whole if name in SERIES] in ([], ["time"])
