"""The thread count of the compiled sweeps (contactlab.threads): checked by name, a matter of
speed only (the same numbers, bit for bit, on one thread as on two), and in "auto" mode chosen
by measuring which count steps faster."""

import json

import numba
import numpy as np
import pytest
from test_sweeps import problem, sphere_lattice

from contactlab import InputError, simulate, threads
from contactlab.methods import sequential

TWO_THREADS = pytest.mark.skipif(
    numba.config.NUMBA_NUM_THREADS < 2, reason="needs NUMBA_NUM_THREADS ≥ 2 to run a sweep on two threads"
)


@pytest.mark.parametrize("given, expected", [("auto", "auto"), ("AUTO", "auto"), (1, 1), ("1", 1), (None, "auto")])
def test_thread_settings_are_read(given, expected):
    assert threads.check_threads(given) == expected


@pytest.mark.parametrize("given", [0, -1, "two", 1.5, True, "1.0"])
def test_bad_thread_settings_are_refused_by_name(given):
    with pytest.raises(InputError, match="^--threads: expected 'auto' or a whole number"):
        threads.check_threads(given, "--threads")


def test_more_threads_than_numba_has_names_the_variable_that_allows_them():
    with pytest.raises(InputError, match="NUMBA_NUM_THREADS"):
        threads.check_threads(threads.available_threads() + 1)


def test_set_threads_is_the_default_of_later_runs(monkeypatch):
    monkeypatch.setattr(threads, "_default", threads.AUTO)
    threads.set_threads(1)
    assert threads.check_threads(None) == 1
    threads.set_threads(None)
    assert threads.check_threads(None) == "auto"


@TWO_THREADS
def test_a_two_group_sweep_is_bit_for_bit_the_same_on_one_thread_and_on_two():
    model = sphere_lattice(friction=0.5)
    state, contacts, rows, order, u0, target = problem(model)
    grouped, starts = sequential.sweep_groups(rows, contacts, state, order, groups=2, min_contacts=0)
    assert len(starts) == 4  # two parallel groups and the spanning one
    results = []
    saved = numba.get_num_threads()
    try:
        for count in (1, 2):
            numba.set_num_threads(count)
            u = u0.copy()
            lam, sweeps, change = sequential.solve_sequential_impulses(
                rows, contacts.friction, target, u, (40, -1.0), np.zeros((contacts.count, 3)), (grouped, starts)
            )
            results.append((lam, u, change))
    finally:
        numba.set_num_threads(saved)
    np.testing.assert_array_equal(results[0][0], results[1][0])
    np.testing.assert_array_equal(results[0][1], results[1][1])
    assert results[0][2] == results[1][2]


@TWO_THREADS
@pytest.mark.parametrize("options", [{}, {"substeps": 4, "substep_when": "always"}], ids=["whole", "substepped"])
def test_a_run_is_bit_for_bit_the_same_on_any_thread_setting(options):
    """A lattice of 512 spheres makes over 1000 contacts, so the sweeps run in two groups (in each
    substep too, ``sequential.solve_in_substeps``)."""
    model = sphere_lattice(side=8, layers=8, friction=0.5)
    runs = {
        setting: simulate(model, "constraints", 1 / 240, 8 / 240, options, threads=setting)
        for setting in (1, 2, "auto")
    }
    assert runs[1].summary["max_contacts"] >= sequential.PARALLEL_MIN_CONTACTS
    assert runs[1].summary["threads"] == {"setting": 1, "available": threads.available_threads(), "steps_at": {"1": 8}}
    assert runs[2].summary["threads"]["steps_at"] == {"2": 8}
    for setting in (2, "auto"):
        for name in ("body_position", "body_orientation", "body_velocity", "solver_residual"):
            np.testing.assert_array_equal(runs[setting].arrays[name], runs[1].arrays[name])
    assert numba.get_num_threads() == threads.available_threads()  # put back after each run


class FakeNumba:
    """Stands in for numba's thread calls, recording what the chooser set."""

    def __init__(self, most):
        self.config = type("config", (), {"NUMBA_NUM_THREADS": most})
        self.current = most
        self.history = []

    def set_num_threads(self, count):
        self.current = count
        self.history.append(count)

    def get_num_threads(self):
        return self.current


def drive(chooser, fake, step_seconds, steps):
    """Run ``steps`` steps, each taking step_seconds[threads now] seconds."""
    for _ in range(steps):
        chooser.before_step()
        chooser.after_step(step_seconds[fake.current])


@pytest.fixture
def fake(monkeypatch):
    stand_in = FakeNumba(2)
    monkeypatch.setattr(threads, "numba", stand_in)
    monkeypatch.setattr(threads, "available_threads", lambda: stand_in.config.NUMBA_NUM_THREADS)
    return stand_in


def test_auto_keeps_two_threads_where_they_are_faster(fake):
    chooser = threads.ThreadChooser("auto", trial_steps=4, hold_steps=10)
    drive(chooser, fake, {1: 0.010, 2: 0.006}, 8)
    assert fake.history == [1] * 4 + [2] * 4  # the trial: one thread first
    drive(chooser, fake, {1: 0.010, 2: 0.006}, 10)
    assert fake.history[8:] == [2] * 10  # the verdict held for 10 steps
    assert chooser.counts == {1: 4, 2: 14}


def test_auto_falls_back_to_one_thread_on_a_busy_machine_and_gives_up_a_hopeless_trial(fake):
    chooser = threads.ThreadChooser("auto", trial_steps=4, hold_steps=10)
    drive(chooser, fake, {1: 0.030, 2: 0.500}, 5)  # 4 steps on one, 1 on two: hopeless
    assert fake.history == [1, 1, 1, 1, 2]
    drive(chooser, fake, {1: 0.030, 2: 0.500}, 10)
    assert fake.history[5:] == [1] * 10


def test_auto_follows_the_load_and_holds_a_repeated_verdict_longer(fake):
    chooser = threads.ThreadChooser("auto", trial_steps=2, hold_steps=4, longest_hold=16)
    busy, idle = {1: 0.03, 2: 0.04}, {1: 0.03, 2: 0.02}  # 0.04: slower, but not enough to give up
    drive(chooser, fake, busy, 4)  # trial (2 + 2): one thread wins
    assert chooser.hold == 4
    drive(chooser, fake, busy, 4 + 4)  # hold, trial again: same verdict
    assert chooser.hold == 8
    drive(chooser, fake, idle, 8 + 4)  # the load went away: two threads win
    assert chooser.hold == 4 and fake.history[-1] == 2
    drive(chooser, fake, idle, 4)
    assert fake.history[-4:] == [2] * 4


def test_a_verdict_is_tried_again_once_the_steps_cost_more_than_in_its_trial(fake):
    """A pile timed while it falls (both counts alike, one thread wins by a hair) lands: its steps
    cost 20× more, and a new trial starts at the first such step instead of after the hold; then
    two threads win. Steps within the factor keep the verdict for its hold."""
    chooser = threads.ThreadChooser("auto", trial_steps=2, hold_steps=50, retry_at=2.0)
    falling, landed = {1: 0.00036, 2: 0.00037}, {1: 0.0106, 2: 0.0068}
    drive(chooser, fake, falling, 4)  # trial: one thread wins
    assert fake.history == [1, 1, 2, 2] and chooser.hold == 50
    drive(chooser, fake, {1: 0.0005, 2: 0.0005}, 10)  # 1.4×: the verdict holds
    assert fake.history[4:] == [1] * 10
    drive(chooser, fake, landed, 1)  # 29× the trial's step: a new trial at once
    drive(chooser, fake, landed, 4)
    assert fake.history[15:] == [1, 1, 2, 2]
    drive(chooser, fake, landed, 5)
    assert fake.history[-5:] == [2] * 5
    # chunks of held steps report per step alike (the compiled loop)
    chooser.before_step(5)
    chooser.after_steps(5, 5 * 0.0068)
    assert chooser.steps_at_this_count() > 1  # same cost: still held
    chooser.before_step(5)
    chooser.after_steps(5, 5 * 0.03)
    assert chooser.steps_at_this_count() == 1  # 4.4×: trial


def test_a_fixed_count_is_set_before_every_step_and_never_tried_otherwise(fake):
    chooser = threads.ThreadChooser(1)
    drive(chooser, fake, {1: 0.01, 2: 0.001}, 20)
    assert fake.history == [1] * 20
    with chooser:
        pass
    assert fake.current == 2  # the process's count put back


def test_auto_makes_no_trials_where_nothing_runs_in_parallel(fake):
    chooser = threads.ThreadChooser("auto", trial_steps=4, hold_steps=10)
    chooser.nothing_parallel()
    assert chooser.steps_at_this_count() is None  # no report due: the loop may run the whole run
    drive(chooser, fake, {1: 0.01, 2: 0.001}, 20)  # two threads "faster": never tried
    assert fake.history == [1] * 20
    fixed = threads.ThreadChooser(2)
    fixed.nothing_parallel()  # a count asked for is kept
    drive(fixed, fake, {1: 0.01, 2: 0.01}, 3)
    assert fake.history[20:] == [2] * 3


@TWO_THREADS
def test_a_small_scene_in_the_compiled_loop_runs_on_one_thread_without_trials():
    from contactlab import ModelBuilder

    b = ModelBuilder()
    b.add_body("sphere", radius=0.1, mass=1.0, position=(0, 0, 1.0))
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0)
    run = simulate(b.finalize(), "impulse", 0.01, 0.5, compiled_loop=True, threads="auto")
    assert run.summary["compiled_loop"]
    assert run.summary["threads"]["steps_at"] == {"1": 50}


def test_the_command_line_takes_a_thread_count_and_refuses_a_bad_one(tmp_path):
    from test_cli import contactlab

    result = contactlab(
        "run",
        "sliding_block",
        "--duration",
        "0.05",
        "--dt",
        "0.001",
        "--threads",
        "1",
        "--json",
        "--no-plots",
        cwd=tmp_path,
    )
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["threads"]["steps_at"] == {"1": 50}
    elsewhere = tmp_path / "bad"
    elsewhere.mkdir()
    bad = contactlab("run", "sliding_block", "--threads", "none", cwd=elsewhere)
    assert bad.returncode == 2
    assert bad.stderr.strip().splitlines() == [
        "error: sliding_block: --threads: expected 'auto' or a whole number of threads ≥ 1, found 'none'"
    ]
    assert list(elsewhere.iterdir()) == []  # nothing written
