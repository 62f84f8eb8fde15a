"""contactlab.plots: four PNGs of a run, the same four comparing runs, nothing left on failure."""

import os

import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.image import imread

from contactlab import plots
from contactlab.scene import load_scene
from contactlab.simulation import simulate


def _run(scene_name, method, duration):
    scene = load_scene(scene_name, [f"simulation.method={method}", f"simulation.duration={duration}"])
    return simulate(
        scene.model, method, scene.dt, scene.duration, scene.method_options.get(method), scene.integrator
    ).arrays


@pytest.fixture(scope="module")
def ball():
    """A ball that lands at 0.45 s: bodies, contacts and solver sweeps."""
    return _run("bouncing_ball", "impulse", 0.6)


@pytest.fixture(scope="module")
def cloth():
    """The first steps of the cloth drape: particles only, no bodies."""
    return _run("cloth_drape", "projection", 0.05)


@pytest.fixture(scope="module")
def runs():
    """The bouncing ball with three methods, for the comparison."""
    return {method: _run("bouncing_ball", method, 0.6) for method in ("penalty", "projection", "impulse")}


def _assert_picture(path):
    image = imread(path)
    assert image.shape[:2] == (450, 800), path
    pixels = np.round(image[..., :3] * 255).astype(np.uint32)
    assert pixels.std() > 5, f"{path} looks blank"
    colours = np.unique(pixels[..., 0] << 16 | pixels[..., 1] << 8 | pixels[..., 2])
    assert len(colours) > 20, f"{path} has hardly any colours"


@pytest.mark.parametrize("name", ["ball", "cloth"])
def test_write_plots_writes_four_800_by_450_pictures_that_are_not_blank(name, request, tmp_path):
    arrays = request.getfixturevalue(name)
    directory = tmp_path / "plots" / "nested"
    paths = plots.write_plots(arrays, str(directory), title=f"{name} — test")
    assert set(paths) == set(plots.PLOTS)
    assert sorted(os.listdir(directory)) == sorted(f"{plot}.png" for plot in plots.PLOTS)  # no temporaries
    for plot, path in paths.items():
        assert path == str(directory / f"{plot}.png")
        _assert_picture(path)


def test_one_run_energy_shows_kinetic_potential_elastic_and_total(ball):
    figures = plots.build_figures({"impulse": ball}, components=True)
    (ax,) = figures["energy"].axes
    labels = [line.get_label() for line in ax.get_lines()]
    assert labels == ["kinetic", "potential", "elastic (contact springs)", "total"]
    total = ax.get_lines()[-1].get_ydata()
    assert np.allclose(total, ball["energy_kinetic"] + ball["energy_potential"] + ball["energy_elastic"])
    assert ax.get_xlabel() == "time (s)" and ax.get_ylabel() == "energy (J)"


def test_comparison_draws_one_line_per_method_in_every_plot(runs):
    figures = plots.build_figures(runs)
    assert set(figures) == set(plots.PLOTS)
    for name, figure in figures.items():
        assert isinstance(figure, Figure)
        ax = figure.axes[0]
        assert len(ax.get_lines()) == len(runs), name
        assert [text.get_text().split(" (")[0] for text in ax.get_legend().get_texts()] == list(runs), name
        assert ax.get_xlabel() in ("time (s)", "")
    energy = figures["energy"].axes[0]
    assert energy.get_ylabel() == "total energy (J)"
    for line, arrays in zip(energy.get_lines(), runs.values()):  # each method's total energy
        assert np.allclose(line.get_ydata(), plots.total_energy(arrays))
    penetration = figures["penetration"].axes[0]
    assert penetration.get_ylabel() == "max penetration (mm)"
    assert np.allclose(penetration.get_lines()[0].get_ydata(), runs["penalty"]["max_penetration"] * 1000)
    residual, iterations = figures["residual"].axes
    assert residual.get_ylabel() == plots.RESIDUAL_LABEL and iterations.get_ylabel() == "iterations"
    assert len(iterations.get_lines()) == len(runs)
    assert "units differ by method" in figures["residual"]._suptitle.get_text()
    assert "penalty (no solver)" in [text.get_text() for text in residual.get_legend().get_texts()]


def test_a_method_keeps_its_colour_whichever_others_ran(runs):
    alone = plots.build_figures({"impulse": runs["impulse"]})["penetration"].axes[0].get_lines()[0]
    together = plots.build_figures(runs)["penetration"].axes[0].get_lines()[2]
    assert together.get_label() == alone.get_label() == "impulse"
    assert (together.get_color(), together.get_linestyle()) == (alone.get_color(), alone.get_linestyle())


def test_write_comparison_plots_writes_the_four_pictures(runs, tmp_path):
    paths = plots.write_comparison_plots(runs, str(tmp_path), title="bouncing_ball")
    assert set(paths) == set(plots.PLOTS)
    for path in paths.values():
        _assert_picture(path)


def test_residual_gets_a_log_axis_only_when_it_spans_decades(ball):
    spread = dict(
        ball,
        solver_residual=np.geomspace(1e-9, 1e-3, len(ball["time"])),
        solver_iterations=np.ones(len(ball["time"]), dtype=int),
    )
    narrow = dict(spread, solver_residual=np.linspace(1.0, 2.0, len(ball["time"])))
    assert plots.build_figures({"a": spread})["residual"].axes[0].get_yscale() == "log"
    assert plots.build_figures({"a": narrow})["residual"].axes[0].get_yscale() == "linear"


def test_a_failure_leaves_no_file_and_no_folder_it_created(ball, tmp_path, monkeypatch):
    written = []
    original = Figure.savefig

    def failing_savefig(self, path, **kwargs):
        if len(written) == 2:
            raise OSError("disk full")
        written.append(path)
        return original(self, path, **kwargs)

    monkeypatch.setattr(Figure, "savefig", failing_savefig)
    directory = tmp_path / "plots"
    with pytest.raises(OSError, match="disk full"):
        plots.write_plots(ball, str(directory))
    assert len(written) == 2 and not directory.exists()

    directory.mkdir()  # a folder that was there stays, empty
    written.clear()
    with pytest.raises(OSError):
        plots.write_comparison_plots({"impulse": ball}, str(directory))
    assert os.listdir(directory) == []

    monkeypatch.undo()
    incomplete = {key: value for key, value in ball.items() if key != "max_penetration"}
    with pytest.raises(KeyError):
        plots.write_plots(incomplete, str(tmp_path / "never"))
    assert not (tmp_path / "never").exists()
