"""Issue 36, deliverable 6: what a run costs beyond its steps. A study runs one model many times;
what is the same every run is done once per model, the compiled loop records straight into the
recorder, and a tiny run reaches its full chunk of steps in few calls — with the same numbers."""

import numpy as np
import pytest
from conftest import ball_on_plane

from contactlab import collision, health, simulate
from contactlab.diagnostics import SERIES
from contactlab.methods import velocity_loop
from contactlab.record import Recorder, series_rows


def _counting(monkeypatch, owner, name):
    """Wrap ``owner.name`` to count its calls; returns the list each call appends its arguments to."""
    calls = []
    real = getattr(owner, name)

    def counted(*args, **kwargs):
        calls.append(args)
        return real(*args, **kwargs)

    monkeypatch.setattr(owner, name, counted)
    return calls


def test_a_rerun_from_the_initial_state_makes_no_collision_pass_in_python(monkeypatch):
    """The plausibility check's start depths are kept with the model for its initial positions,
    and the loop's own samples answer the depth checks: a second run of a ball collides only in
    the compiled loop. A state at other positions gets its own pass."""
    model = ball_on_plane(height=0.2)
    first = simulate(model, "impulse", 0.01, 0.5, compiled_loop=True)
    passes = _counting(monkeypatch, collision, "collide_keeping")
    again = simulate(model, "impulse", 0.01, 0.5, compiled_loop=True)
    assert passes == []
    np.testing.assert_array_equal(again.arrays["body_position"], first.arrays["body_position"])
    assert again.summary["max_penetration"] == first.summary["max_penetration"]
    moved = model.state()
    moved.body_position[0, 2] -= 0.05
    simulate(model, "impulse", 0.01, 0.5, state=moved, compiled_loop=True)
    assert len(passes) == 1


def test_a_ball_starting_deep_is_warned_of_on_every_run_from_its_kept_check():
    from contactlab.plausibility import PlausibilityWarning

    model = ball_on_plane(height=-0.05)  # 5 cm into the floor, half its radius
    for _ in range(2):
        with pytest.warns(PlausibilityWarning, match="starts 0.05 m deep"):
            simulate(model, "impulse", 0.01, 0.01, allow_divergence=True)


def test_a_tiny_run_on_a_compiled_loop_reaches_its_full_chunk_in_four_calls(monkeypatch):
    """The first step alone (it may compile); where it compiled nothing its pace sizes the next
    chunk (16 steps at most), then 256, then the rest: four calls into the loop for 720 steps."""
    model = ball_on_plane()
    simulate(model, "impulse", 1 / 240, 3.0, compiled_loop=True)
    calls = _counting(monkeypatch, velocity_loop.LoopStepper, "advance")
    run = simulate(model, "impulse", 1 / 240, 3.0)
    assert run.summary["stepping"] == "compiled loop"
    chunks = [args[1] for args in calls]
    assert chunks[0] == 1 and chunks[1] > 1 and sum(chunks) == 720
    assert len(chunks) <= 4


def test_samples_reserved_committed_and_extended_across_chunks_are_one_trajectory(tmp_path):
    """The Recorder's buffer holds 4 samples here: rows reserved and written in place, samples
    copied in, a batch larger than the buffer, and a sample that stops short all come out in
    order, in memory and streamed alike, with the summary's totals."""
    from contactlab.record import streaming_recorder
    from contactlab.store import TrajectoryFile

    model = ball_on_plane()
    rows = series_rows(model)
    total = 15
    values = {
        name: np.random.default_rng(len(name)).random((total, *shape)).astype(dtype)
        for name, (shape, dtype) in rows.items()
    }
    values["time"] = np.arange(total, dtype=float)

    def record(recorder):
        done = 0
        for count, how, written in (
            (3, "reserve", 3),
            (2, "extend", 2),
            (6, "reserve", 6),
            (3, "reserve", 2),
            (2, "extend", 2),
        ):
            part = {name: array[done : done + written] for name, array in values.items()}
            if how == "extend":
                recorder.extend(part)
            else:
                space = recorder.reserve(count)
                assert list(space) == list(SERIES) and all(len(array) == count for array in space.values())
                for name in SERIES:
                    space[name][:written] = part[name]
                recorder.commit(written)
            done += written
        return done

    memory = Recorder(model, samples=4)
    made = record(memory)
    kept = memory.arrays()
    path = str(tmp_path / "trajectory.h5")
    streamed = streaming_recorder(model, 1, path, 4)
    record(streamed)
    streamed.flush()
    read = TrajectoryFile(streamed.sink.finish("complete"))
    for name in SERIES:
        np.testing.assert_array_equal(kept[name], values[name][:made], err_msg=name)
        np.testing.assert_array_equal(read[name], values[name][:made], err_msg=name)
    assert memory.totals.count == streamed.totals.count == made
    assert memory.totals.last_time == made - 1
    assert memory.latest(("time",))["time"][0] == made - 1


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_an_energy_that_stops_being_finite_is_caught_whichever_way(bad):
    """The energy check's quick pass (every row finite and within the gain) lets none of NaN,
    +inf or −inf by: each stops the run as not finite, at its row."""
    model = ball_on_plane()
    checks = health.Health(model, model.state(), 1e-3)
    zero = np.zeros(5)
    kinetic = np.array([1.0, 1.0, 1.0, bad, 1.0])
    found = checks.check_samples(
        {"time": np.arange(5.0), "energy_kinetic": kinetic, "energy_potential": zero, "energy_elastic": zero}
    )
    assert found.check == "finite" and found.time == 3.0
