"""contactlab.compare: the methods side by side, its CSV, Markdown and HTML reports."""

import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from html.parser import HTMLParser
from urllib.parse import unquote, urlparse

import numpy as np
import pytest
from conftest import alive_in_group, interruptible, messages
from matplotlib.image import imread

from contactlab import compare as compare_module
from contactlab import simulation
from contactlab.compare import compare, report, run
from contactlab.errors import InputError
from contactlab.methods import AVAILABLE
from contactlab.store import open_trajectory

PYRAMID = "box_pyramid"


@pytest.fixture(scope="module")
def pyramid(tmp_path_factory):
    """All four methods on the pyramid for 0.2 s (48 steps), no video: a scene with an obstacle."""
    return compare(PYRAMID, out=str(tmp_path_factory.mktemp("pyramid")), duration=0.2, video=False)


@pytest.fixture(scope="module")
def ball(tmp_path_factory):
    """The bouncing ball past its first apex; penalty made to blow up by a stiffness of 1e12 N/m
    kept explicit."""
    return compare(
        "bouncing_ball",
        ["impulse", "penalty"],
        str(tmp_path_factory.mktemp("ball")),
        overrides=["method.penalty.stiffness=1e12", "method.penalty.implicit_springs=never"],
        duration=0.9,
        video=False,
    )


@pytest.fixture(scope="module")
def cradle(tmp_path_factory):
    """Newton's cradle: no gravity, no obstacles, so momentum must be conserved."""
    return compare(
        "newtons_cradle", "impulse,projection", str(tmp_path_factory.mktemp("cradle")), duration=0.3, video=False
    )


def _csv_rows(result):
    with open(result.csv, newline="", encoding="utf-8") as stream:
        return list(csv.DictReader(stream))


def _trajectory(result, method):
    data = open_trajectory(os.path.join(result.out, method, "trajectory.h5"))
    assert data.status == "complete"
    return {key: data[key] for key in data}


def _summary(result, method):
    with open(os.path.join(result.out, method, "summary.json"), encoding="utf-8") as stream:
        return json.load(stream)


class _Links(HTMLParser):
    """Every src, href and poster of a page, and the tags it uses."""

    def __init__(self):
        super().__init__()
        self.links, self.tags = [], []

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        self.links += [value for name, value in attrs if name in ("src", "href", "poster")]


def _links(path):
    parser = _Links()
    with open(path, encoding="utf-8") as stream:
        parser.feed(stream.read())
    parser.close()
    return parser


def _assert_links_resolve(result):
    parser = _links(result.report_html)
    assert parser.links
    for link in parser.links:
        parts = urlparse(link)
        assert not parts.scheme and not parts.netloc and not link.startswith("/"), link
        assert os.path.isfile(os.path.join(result.out, unquote(parts.path))), link
    return parser


# ---- the numbers --------------------------------------------------------------------------------


def test_one_csv_row_per_method_matching_each_summary(pyramid):
    rows = _csv_rows(pyramid)
    assert [row["method"] for row in rows] == list(AVAILABLE)
    assert rows == [{key: report._csv_value(value) for key, value in row.items()} for row in pyramid.rows]
    for row in rows:
        summary = _summary(pyramid, row["method"])
        assert row["status"] == "ok"
        assert int(row["steps"]) == summary["steps"] == 48
        assert float(row["steps_per_second"]) == summary["steps_per_second"]
        assert float(row["wall_seconds"]) == summary["wall_seconds"]
        assert float(row["max_penetration_mm"]) == pytest.approx(summary["max_penetration"] * 1000, rel=1e-12)
        assert int(row["max_solver_iterations"]) == summary["solver"]["max_iterations"]
        sweeps = _trajectory(pyramid, row["method"])["solver_iterations"]
        assert len(sweeps) == summary["steps"] + 1  # every step recorded, and the start
        assert (
            float(row["mean_solver_iterations"])
            == summary["solver"]["mean_iterations"]
            == pytest.approx(sweeps[1:].mean(), rel=1e-12)
        )
        assert float(row["dt_s"]) == summary["dt"] and row["integrator"] == summary["integrator"]


def test_energy_drift_and_mean_penetration_are_those_of_the_trajectory(pyramid):
    for row in pyramid.rows:
        arrays = _trajectory(pyramid, row["method"])
        total = arrays["energy_kinetic"] + arrays["energy_potential"] + arrays["energy_elastic"]
        assert row["energy_drift_J"] == pytest.approx(total[-1] - total[0], rel=1e-12, abs=1e-15)
        assert row["mean_penetration_mm"] == pytest.approx(arrays["max_penetration"].mean() * 1000, rel=1e-12)
        # the scale: 15 cubes 1 kg, centres 0.1 m per level above the lowest: g (4·0.1 + 3·0.2 + 2·0.3 + 0.4)
        assert row["energy_drift_relative"] * 9.81 * 2.0 == pytest.approx(row["energy_drift_J"], rel=0.01)


def test_every_method_reports_its_solver_and_penalty_its_implicit_springs(pyramid):
    """The pyramid's loads make penalty's springs too stiff for the explicit step: it steps them by
    backward Euler (passes of the active set, relative linear residual), and the row says so."""
    rows = {row["method"]: row for row in pyramid.rows}
    assert _summary(pyramid, "penalty")["implicit_spring_steps"] > 0
    for method in ("penalty", "projection", "impulse", "constraints"):
        assert rows[method]["max_solver_iterations"] > 0
        assert rows[method]["max_solver_residual"] == _summary(pyramid, method)["solver"]["max_residual"]


def test_a_run_without_a_solver_reports_no_residual(tmp_path):
    result = compare("bouncing_ball", ["penalty"], str(tmp_path / "ball"), duration=0.2, video=False)
    assert result.rows[0]["max_solver_iterations"] == 0 and result.rows[0]["max_solver_residual"] is None
    assert _csv_rows(result)[0]["max_solver_residual"] == ""


def test_momentum_drift_is_not_reported_with_obstacles(pyramid):
    assert all(row["momentum_drift_Ns"] == "n/a" for row in pyramid.rows)
    assert all(row["momentum_drift_Ns"] == "n/a" for row in _csv_rows(pyramid))
    with open(pyramid.report_md, encoding="utf-8") as stream:
        assert "Momentum drift is n/a: the scene has static obstacles" in stream.read()


def test_momentum_drift_without_obstacles_is_rounding_for_impulses(cradle):
    # Impulses act in equal and opposite pairs, so P changes only by rounding: ~1e-16 of
    # |P| = 1 kg m/s per impulse, some thousand impulses in 300 steps -> far below 1e-9 N s.
    rows = {row["method"]: row for row in cradle.rows}
    assert rows["impulse"]["momentum_drift_Ns"] < 1e-9
    arrays = _trajectory(cradle, "impulse")
    momentum = arrays["body_velocity"].sum(axis=1)  # 1 kg balls
    assert np.linalg.norm(momentum[-1] - momentum[0]) == pytest.approx(rows["impulse"]["momentum_drift_Ns"], abs=1e-15)
    assert isinstance(rows["projection"]["momentum_drift_Ns"], float)  # reported, whatever it is
    with open(cradle.report_md, encoding="utf-8") as stream:
        assert "is a conservation check" in stream.read()


def test_closed_form_checks_become_error_columns_with_expected_and_measured_in_the_report(ball):
    closed_form = pytest.importorskip("contactlab.closed_form")
    arrays = _trajectory(ball, "impulse")
    from contactlab.scene import load_scene

    model = load_scene("bouncing_ball").model
    checks = closed_form.checks("bouncing_ball", model, arrays)
    assert checks
    rows = {row["method"]: row for row in ball.rows}
    first = checks[0]
    column = f"{first.quantity} error ({first.unit})"
    assert rows["impulse"][column] == pytest.approx(first.error, abs=1e-12)
    assert abs(first.error) < 1e-3  # 0.64 m, to a fraction of a mm
    assert rows["penalty"][column] is None  # it blew up
    assert column in _csv_rows(ball)[0]
    with open(ball.report_md, encoding="utf-8") as stream:
        report = stream.read()
    assert f"{first.quantity} ({first.unit}, expected {first.expected:.4g})" in report  # table heading
    assert f"**{first.quantity}** ({first.unit}): expected {first.expected:.6g}" in report  # the check line


def test_the_verdicts_match_the_checks_and_the_paragraph_names_what_was_missed(cradle):
    # Newton's cradle: impulses pass the velocity down the row; projection (inelastic) does not
    rows = {row["method"]: row for row in cradle.rows}
    assert rows["impulse"]["expectations"] == "pass (2 of 2)"
    checks = {check.quantity: check for check in cradle.checks["projection"]}
    failed = [check for check in checks.values() if check.passed is False]
    assert failed and rows["projection"]["expectations"] == f"FAIL ({2 - len(failed)} of 2)"
    assert "The scene's stated expectations: met by impulse; missed by projection (" in cradle.summary_text
    quantity = failed[0].quantity
    assert f"{quantity} {failed[0].measured:.3g} m/s, expected {failed[0].expected:.3g} ± " in cradle.summary_text
    with open(cradle.report_md, encoding="utf-8") as stream:
        report = stream.read()
    assert "FAIL" in report and "What the columns mean:" in report and "**expectations met**" in report


def test_speeds_whose_middle_halves_overlap_are_called_within_noise():
    from contactlab.compare.report import _speed_sentence
    from contactlab.compare.run import Outcome

    def outcome(name, median, low, high):
        made = Outcome(name, None)
        made.row = {
            "steps_per_second": median,
            "steps_per_second_median": median,
            "steps_per_second_low": low,
            "steps_per_second_high": high,
        }
        return made

    fast, close, slow = outcome("a", 1000, 950, 1050), outcome("b", 980, 900, 990), outcome("c", 500, 480, 520)
    assert _speed_sentence([close, slow, fast]) == (
        "Fastest: a (1,000 steps/s, median); b within noise of it; slowest: c (500 steps/s)."
    )
    assert _speed_sentence([fast, close]) == (
        "Fastest: a (1,000 steps/s, median); b within noise of it (their middle halves overlap)."
    )
    # issue 59: runs timed in one window each (quartiles = median) were ranked by one timing
    once, short = outcome("d", 1300, 1300, 1300), outcome("e", 700, None, None)
    for ran, unspread in (([fast, once, slow], "d"), ([short, fast], "e")):
        assert _speed_sentence(ran) == (
            f"Speed: not ranked: {unspread} stepped too briefly to be timed in more than one ~0.1 s window, "
            "so no spread tells a difference from the machine's noise (steps/s in the table)."
        )


def _drift_outcome(name, drift):
    made = run.Outcome(name, None)
    made.row = {"energy_drift_J": drift}
    return made


def test_energy_drifts_within_noise_are_not_ranked():
    """Issue 37: box_pushed's drifts of 0.125 J (three methods) and 0.126 J (penalty) were
    ranked best and worst; 1.5 mJ apart is within 2 % of the larger."""
    exact = [_drift_outcome(name, -0.12500000054) for name in ("projection", "impulse", "constraints")]
    assert report._energy_sentence([*exact, _drift_outcome("penalty", -0.12645946)]) == (
        "Energy kept: all within noise of one another (total energy changed by 0.125 J to 0.126 J)."
    )
    rounding = [_drift_outcome("impulse", 1e-12), _drift_outcome("projection", -3e-10)]  # under 1 µJ apart
    assert report._energy_sentence(rounding).startswith("Energy kept: all within noise of one another")
    apart = [_drift_outcome("a", -0.125), _drift_outcome("b", 0.1262), _drift_outcome("c", -0.2)]
    assert report._energy_sentence(apart) == (
        "Energy kept best: a and b (total energy changed by 0.125 J to 0.126 J); "
        "worst: c (total energy changed by 0.2 J)."
    )
    assert report._energy_sentence([apart[2]]) == "Energy kept best: c (total energy changed by 0.2 J)."


def test_penetrations_of_rounding_size_are_not_ranked():
    """Issue 37: on box_pushed the report named projection (9.4e-8 mm) least penetrating and
    impulse (3.4e-7 mm) behind it: both are no overlap at all. Depths under 0.001 mm are alike."""

    def outcome(name, depth):
        made = run.Outcome(name, None)
        made.row = {"max_penetration_mm": depth}
        return made

    def sentence(outcomes):
        return report._ranking(
            outcomes,
            ("Least penetration", "deepest", "Least penetration: all the same"),
            lambda o: o.row["max_penetration_mm"],
            True,
            lambda v: f"{v:.3g} mm",
            report._penetration_alike,
        )

    rounding = [outcome("projection", 9.4e-8), outcome("impulse", 3.4e-7), outcome("constraints", 2e-7)]
    assert sentence(rounding) == "Least penetration: all the same (9.4e-08 mm to 3.4e-07 mm)."
    with_penalty = sentence([*rounding, outcome("penalty", 0.3)])
    assert with_penalty == (
        "Least penetration: projection, impulse and constraints (9.4e-08 mm to 3.4e-07 mm); deepest: penalty (0.3 mm)."
    )
    apart = sentence([outcome("a", 0.002), outcome("b", 0.003)])  # past the floor: ranked as shown
    assert apart == "Least penetration: a (0.002 mm); deepest: b (0.003 mm)."


def test_the_energy_scale_leaves_the_contact_springs_out():
    """Issue 37: penalty's drift was divided by its own springs' peak (1.01 J on box_pushed), the
    other methods' by the scene's 0.25 J. The scale is the most kinetic + potential energy
    above the lowest potential energy: here 2 J + 1 J − (−1 J) = 4 J, whatever the springs held."""
    from contactlab import ModelBuilder
    from contactlab.compare import energy_scale

    builder = ModelBuilder(gravity=(0, 0, -9.81))
    builder.add_body("sphere", radius=0.1, mass=1.0, position=(0, 0, 1.0))
    model = builder.finalize()
    arrays = {
        "energy_kinetic": np.array([0.0, 2.0, 1.0]),
        "energy_potential": np.array([1.0, 1.0, -1.0]),
        "energy_elastic": np.array([0.0, 0.0, 0.0]),
        "body_position": np.zeros((3, 1, 3)),
        "particle_position": np.zeros((3, 0, 3)),
    }
    assert energy_scale(model, arrays) == 4.0
    arrays["energy_elastic"] = np.array([0.0, 10.0, 0.0])  # a spring's peak: no other scale
    assert energy_scale(model, arrays) == 4.0


def test_a_run_measures_its_rate_in_windows_and_gives_median_and_quartiles(cradle):
    from contactlab.simulation import WINDOW_SECONDS, Tally

    tally = Tally()
    tally.timed(1, 5.0, 4.0)  # the first step: compiling, never a measurement
    for steps in (10, 20, 30, 40):  # four windows of WINDOW_SECONDS: 100 to 400 steps/s
        tally.timed(2, WINDOW_SECONDS, 0.0, steps / (0.1 / WINDOW_SECONDS))
    tally.timed(3, 1.0, 0.5, 1000)  # steps that compiled something: not a measurement
    assert tally.window_rates == pytest.approx([100.0, 200.0, 300.0, 400.0])
    assert tally.rate_spread() == pytest.approx({"median": 250.0, "low": 175.0, "high": 325.0, "windows": 4})
    summary = _summary(cradle, "impulse")["steps_per_second_spread"]
    assert summary["low"] <= summary["median"] <= summary["high"] and summary["windows"] >= 1
    row = {row["method"]: row for row in cradle.rows}["impulse"]
    assert row["steps_per_second_median"] == summary["median"]


# ---- failures -----------------------------------------------------------------------------------


def test_a_method_that_blows_up_is_reported_and_the_others_go_on(ball):
    rows = {row["method"]: row for row in ball.rows}
    assert rows["penalty"]["status"].startswith("blew up at t = ")
    assert float(rows["penalty"]["status"].split("= ")[1].split(" s")[0]) == pytest.approx(0.45, abs=0.02)
    assert rows["penalty"]["max_penetration_mm"] is None and rows["impulse"]["status"] == "ok"
    assert rows["impulse"]["steps"] == 900
    # the run up to the blow-up is kept, marked diverged; no plots or video of it
    assert sorted(os.listdir(os.path.join(ball.out, "penalty"))) == ["summary.json", "trajectory.h5"]
    assert open_trajectory(os.path.join(ball.out, "penalty", "trajectory.h5")).status == "diverged"
    assert _summary(ball, "penalty")["diverged"]["check"] in ("energy", "speed", "depth", "finite")
    assert "penalty blew up at t = " in ball.summary_text
    for path in (ball.report_md, ball.report_html):
        with open(path, encoding="utf-8") as stream:
            text = stream.read()
        assert "blew up at t = " in text and "stiffness 1e+12 N/m" in text  # the health check's advice
    _assert_links_resolve(ball)


def test_unknown_method_is_an_input_error_naming_the_valid_ones(tmp_path):
    out = tmp_path / "never"
    with pytest.raises(InputError) as error:
        compare("bouncing_ball", ["impulse", "teleport"], str(out), video=False)
    assert error.value.field == "--methods"
    assert "teleport" in error.value.message and all(name in error.value.message for name in AVAILABLE)
    with pytest.raises(InputError):
        compare("bouncing_ball", [], str(out), video=False)
    assert not out.exists()


def test_a_bad_scene_stops_everything_before_anything_is_written(tmp_path):
    out = tmp_path / "never"
    with pytest.raises(InputError, match="bodies"):
        compare("bouncing_ball", out=str(out), overrides=["bodies.0.mass=-1"], video=False)
    with pytest.raises(InputError, match="duration"):
        compare("bouncing_ball", out=str(out), duration=-1, video=False)
    with pytest.raises(InputError, match="unknown built-in scene"):
        compare("no_such_scene", out=str(out), video=False)
    assert not out.exists()


def test_methods_rejecting_the_scene_are_left_out_unless_named(tmp_path, monkeypatch):
    real = simulation.simulate  # what Scene.simulate calls, looked up at each call

    def simulate(model, method, *args, **kwargs):
        if method == "projection":
            raise InputError("integrator", "projection cannot run this")
        return real(model, method, *args, **kwargs)

    monkeypatch.setattr(simulation, "simulate", simulate)
    result = compare("bouncing_ball", None, str(tmp_path / "all"), duration=0.02, video=False)
    assert [row["method"] for row in result.rows] == ["penalty", "impulse", "constraints"]
    assert "projection cannot run this" in result.skipped["projection"]
    assert "projection was left out" in result.summary_text
    with pytest.raises(InputError, match="projection cannot run this"):
        compare("bouncing_ball", ["impulse", "projection"], str(tmp_path / "named"), duration=0.02, video=False)
    assert not (tmp_path / "named").exists()


def test_a_failure_while_writing_removes_what_the_comparison_wrote(tmp_path, monkeypatch):
    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(run, "write_comparison_plots", broken)
    out = tmp_path / "a" / "b"
    with pytest.raises(OSError, match="disk full"):
        compare("bouncing_ball", ["impulse", "constraints"], str(out), duration=0.02, video=False)
    assert not (tmp_path / "a").exists()

    out.mkdir(parents=True)  # a folder that was there before stays, with its files
    (out / "mine.txt").write_text("keep")
    with pytest.raises(OSError):
        compare("bouncing_ball", ["impulse"], str(out), duration=0.02, video=False)
    assert os.listdir(out) == ["mine.txt"]


def test_a_comparison_that_fails_leaves_the_earlier_ones_methods_as_they_were(tmp_path, monkeypatch):
    # issue 59: a comparison removes the method folders of an earlier one only once its own
    # reports are written; one that fails before keeps them (and the earlier report naming them)
    compare("bouncing_ball", ["impulse", "constraints"], str(tmp_path), duration=0.02, video=False)

    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(run, "write_comparison_plots", broken)
    with pytest.raises(OSError, match="disk full"):
        compare("bouncing_ball", ["impulse"], str(tmp_path), duration=0.02, video=False)
    assert sorted(os.listdir(tmp_path / "constraints")) == ["plots", "summary.json", "trajectory.h5"]
    assert "constraints" in (tmp_path / "comparison.csv").read_text(encoding="utf-8")


def test_default_output_folder_is_out_scene_compare(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = compare("bouncing_ball", "impulse", duration=0.02, video=False)
    assert result.out == os.path.join("out", "bouncing_ball-compare")
    assert sorted(os.listdir(result.out)) == ["comparison.csv", "impulse", "plots", "report.html", "report.md"]
    assert sorted(os.listdir(os.path.join(result.out, "impulse"))) == ["plots", "summary.json", "trajectory.h5"]
    assert _summary(result, "impulse")["trajectory"] == os.path.join(result.out, "impulse", "trajectory.h5")


# ---- the reports --------------------------------------------------------------------------------


def test_report_md_holds_the_table_links_and_the_summary(pyramid):
    with open(pyramid.report_md, encoding="utf-8") as stream:
        report = stream.read()
    header = next(line for line in report.splitlines() if line.startswith("| method |"))
    assert "max penetration (mm)" in header and "energy drift (J)" in header and "steps/s" in header
    for method in AVAILABLE:
        assert any(line.startswith(f"| {method} | ok |") for line in report.splitlines())
        assert f"({method}/plots/energy.png)" in report and f"({method}/trajectory.h5)" in report
    assert "(plots/energy.png)" in report
    assert pyramid.summary_text in report
    assert "Least penetration:" in pyramid.summary_text
    assert "Fastest:" in pyramid.summary_text or "Speed: not ranked: " in pyramid.summary_text
    assert "Energy kept best:" in pyramid.summary_text


def test_report_html_parses_and_links_only_files_of_the_output(pyramid):
    parser = _assert_links_resolve(pyramid)
    assert "video" not in parser.tags and "link" not in parser.tags  # video=False; no stylesheets
    with open(pyramid.report_html, encoding="utf-8") as stream:
        page = stream.read()
    assert "http://" not in page and "https://" not in page
    assert page.count("<details>") == len(AVAILABLE) and "<table>" in page
    assert 'data-status="pending"' in page


def test_text_is_escaped_in_the_html(tmp_path):
    scene = tmp_path / "odd.toml"
    scene.write_text(
        'description = "<b>bold</b> & \\"quoted\\""\n[simulation]\nduration = 0.02\n'
        '[[bodies]]\nshape = "sphere"\nradius = 0.1\nmass = 1.0\n',
        encoding="utf-8",
    )
    result = compare(str(scene), ["impulse"], str(tmp_path / "out"), video=False)
    with open(result.report_html, encoding="utf-8") as stream:
        page = stream.read()
    assert "<b>bold</b>" not in page and "&lt;b&gt;bold&lt;/b&gt; &amp; &quot;quoted&quot;" in page
    assert result.rows[0]["momentum_drift_Ns"] < 1e-12  # free fall: P(T) − P(0) = M g T


# ---- with videos, in a browser ------------------------------------------------------------------


@pytest.fixture(scope="module")
def with_video(tmp_path_factory):
    pytest.importorskip("contactlab.render")
    return compare(PYRAMID, ["impulse", "penalty"], str(tmp_path_factory.mktemp("video")), duration=0.1, fps=10)


def test_videos_are_written_and_linked(with_video):
    for method in ("impulse", "penalty"):
        files = with_video.files[method]
        for name in ("mp4", "gif", "still"):
            assert os.path.getsize(files[name]) > 0
    parser = _assert_links_resolve(with_video)
    assert parser.tags.count("video") == 2
    assert "impulse/video.mp4" in parser.links and "impulse/still.png" in parser.links
    assert "impulse/video.gif" in parser.links  # the fallback inside


def _chromium():
    return shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")


def test_the_report_displays_in_headless_chromium(with_video, tmp_path):
    browser = _chromium()
    if browser is None:
        pytest.skip("no chromium, chromium-browser or google-chrome executable on PATH")
    url = "file://" + os.path.abspath(with_video.report_html)
    flags = [
        browser,
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--virtual-time-budget=8000",
        f"--user-data-dir={tmp_path / 'profile'}",
    ]
    dom = subprocess.run([*flags, "--dump-dom", url], capture_output=True, text=True, timeout=120).stdout
    assert 'data-status="ok"' in dom, dom[dom.find("<body") :][:300]
    screenshot = tmp_path / "report.png"
    subprocess.run(
        [*flags, f"--screenshot={screenshot}", "--window-size=1280,2000", url], capture_output=True, timeout=120
    )
    image = imread(screenshot)
    assert image.shape[:2] == (2000, 1280)
    assert image[..., :3].std() > 0.05  # not a blank page


def test_the_methods_run_on_a_dask_cluster_give_the_numbers_they_give_one_after_another(tmp_path):
    """workers=2: each method's run and video are a job of a real local cluster (two worker
    processes); every number but the timings is the one the runs in this process give."""
    serial = compare("bouncing_ball", "impulse,penalty", str(tmp_path / "here"), duration=0.5, video=False, workers=1)
    spread = compare("bouncing_ball", "impulse,penalty", str(tmp_path / "cluster"), duration=0.5, fps=10, workers=2)
    timings = set(compare_module.TIMINGS)
    for here, there in zip(serial.rows, spread.rows):  # NaN where a rebound was not reached: equal too
        np.testing.assert_equal(
            {k: v for k, v in here.items() if k not in timings}, {k: v for k, v in there.items() if k not in timings}
        )
    for method in ("impulse", "penalty"):
        files = spread.files[method]
        assert {"mp4", "gif", "still"} <= set(files) and all(os.path.isfile(files[name]) for name in files)
        assert open_trajectory(files["trajectory"]).status == "complete"
    assert not any(name.startswith(".partial-") for _, _, names in os.walk(tmp_path) for name in names)


def test_methods_that_computed_the_same_trajectory_are_said_to_be_one_result(tmp_path):
    """On one bouncing ball, impulses and constraints solve the same one-contact problem the same
    way (their positions differ by rounding only): the report says their numbers are one result;
    penalty's differ and it is not named."""
    result = compare(
        "bouncing_ball", "impulse,constraints,penalty", str(tmp_path / "out"), duration=0.6, video=False, workers=1
    )
    with open(result.report_md, encoding="utf-8") as stream:
        report = stream.read()
    impulse = open_trajectory(os.path.join(result.out, "impulse", "trajectory.h5"))
    constraints = open_trajectory(os.path.join(result.out, "constraints", "trajectory.h5"))
    apart = float(np.max(np.abs(impulse["body_position"] - constraints["body_position"])))
    assert apart < 1e-12
    assert (
        f"- impulse and constraints computed the same trajectory to within rounding (positions apart by "
        f"{apart:.2g} m at most)"
    ) in report
    assert "penalty computed the same" not in report and "and penalty computed" not in report


def _streaming(folder):
    """Whether a run in ``folder``'s method folders is stepping: a trajectory growing under its
    temporary name (past its compilation, which no signal interrupts)."""
    sizes = {}
    for _ in range(2):
        for root, _, names in os.walk(folder):
            for name in names:
                if name.startswith(".partial-") and name.endswith("trajectory.h5"):
                    path = os.path.join(root, name)
                    size = os.path.getsize(path)
                    if sizes.get(path, size) < size:
                        return True
                    sizes[path] = size
        time.sleep(0.2)
    return False


@pytest.mark.parametrize("workers, signum", [(1, signal.SIGTERM), (2, signal.SIGINT)])
def test_a_stopped_compare_lists_exactly_what_it_left_on_either_path(tmp_path, workers, signum):
    """Issue 37: one after another (workers 1) or on a local cluster's workers (2, stopped by a
    terminal's Ctrl-C, which reaches the workers too): within a second and in one line, the
    command names every file it left — each run's trajectory up to the signal — and nothing else
    is there (no temporary file, summary, plot or report)."""
    out = tmp_path / "out"
    command = [sys.executable, "-m", "contactlab", "compare", "bouncing_ball", "--methods", "impulse,constraints"]
    process = subprocess.Popen(
        # an hour: through the compiled loop (where an earlier run cached it) 864,000 steps take
        # seconds, where 60 s of the ball ended before the signal and was kept "complete"
        [*command, "--duration", "3600", "--no-video", "--workers", str(workers), "--out", str(out)],
        cwd=tmp_path,
        preexec_fn=interruptible,
        start_new_session=True,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and process.poll() is None and not _streaming(out):
        pass
    if workers == 1:
        process.send_signal(signum)  # as kill PID does
    else:
        os.killpg(process.pid, signum)  # as a terminal's Ctrl-C: to the command and its workers
    sent = time.monotonic()
    _, stderr = process.communicate(timeout=60)
    took = time.monotonic() - sent
    name = signal.Signals(signum).name
    assert process.returncode == 128 + signum and took < 2.0, (took, stderr)
    lines = [line for line in messages(stderr) if not line.startswith("compiling contact kernels")]
    assert len(lines) == 1 and lines[0].startswith(f"interrupted ({name}); written before it: "), stderr
    listed = set(lines[0].split("written before it: ")[1].split(", "))
    left = {os.path.join(root, name) for root, _, names in os.walk(out) for name in names}
    assert listed == left and listed, (listed, left)
    for path in listed:
        assert os.path.basename(path) == "trajectory.h5" and open_trajectory(path).status == "interrupted"
    assert not alive_in_group(process.pid, 1.0)  # no worker outlived the command
