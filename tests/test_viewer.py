"""The interactive viewer (contactlab.viewer, issue 22): served on loopback, its scene graph,
its clock, compare folders side by side, its errors, and the page drawn in headless Chromium."""

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.request

import numpy as np
import pytest
from conftest import interruptible

from contactlab import ModelBuilder, browser, cli, simulate
from contactlab.compare import compare
from contactlab.errors import InputError
from contactlab.methods import AVAILABLE
from contactlab.record import load_run
from contactlab.sample_contacts import contacts_at
from contactlab.viewer import HOST, Viewer, view


@pytest.fixture(scope="module")
def pyramid(tmp_path_factory):
    """A built-in scene run written by the command line: box_pyramid for 0.1 s."""
    out = str(tmp_path_factory.mktemp("viewer") / "pyramid")
    assert cli.main(["run", "box_pyramid", "--duration", "0.1", "--out", out, "--no-plots"]) == 0
    return out


@pytest.fixture(scope="module")
def compared(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("viewer") / "compare")
    compare("bouncing_ball", "impulse,penalty", out, duration=0.2, video=False, workers=1)
    return out


@pytest.fixture
def viewer(pyramid):
    shown = view(pyramid)
    yield shown
    shown.stop()


def _refused(port):
    with socket.socket() as probe:
        return probe.connect_ex((HOST, port)) != 0


def test_the_server_listens_on_loopback_on_a_free_port_and_stops(pyramid):
    shown = view(pyramid)
    assert shown.url == f"http://127.0.0.1:{shown.port}" and shown.port > 0
    with urllib.request.urlopen(shown.url, timeout=10) as page:
        assert page.status == 200 and b"<html" in page.read(2000).lower()
    shown.stop()
    assert _refused(shown.port)


def test_the_scene_graph_holds_bodies_obstacles_and_contacts_when_toggled(viewer):
    nodes = viewer.nodes()
    assert {f"/run0/bodies/{b}" for b in range(15)} <= set(nodes)
    assert {"/run0/obstacles", "/run0/label"} <= set(nodes)
    assert not any("/contacts/" in name for name in nodes)  # nothing computed while off
    for toggle in ("points", "normals", "forces"):
        viewer.gui[toggle].value = True
    viewer.show_time(0.05)
    viewer.redraw()
    assert {"/run0/contacts/points", "/run0/contacts/normals", "/run0/contacts/forces"} <= set(viewer.nodes())
    contacts = viewer.contacts[0]
    assert len(contacts.points) > 0 and np.allclose(np.linalg.norm(contacts.normals, axis=1), 1.0)
    on_floor = contacts.force_points[:, 2] < 0.005  # the floor holds the whole pyramid up
    weight = viewer.runs[0].model.body_mass.sum() * 9.81
    assert contacts.forces[on_floor, 2].sum() == pytest.approx(weight, rel=0.05)
    viewer.gui["forces"].value = False
    viewer.redraw()
    assert "/run0/contacts/forces" not in viewer.nodes()


def test_the_timeline_moves_the_bodies_to_the_recorded_positions(viewer, pyramid):
    arrays, _ = load_run(pyramid)
    time_, position, orientation = arrays["time"], arrays["body_position"], arrays["body_orientation"]
    for sample in (len(time_) - 1, len(time_) // 2, 0):
        viewer.show_time(time_[sample])
        assert viewer.shown == [sample] and viewer.gui["time"].value == pytest.approx(time_[sample])
        for body, handle in enumerate(viewer.runs[0].bodies):
            np.testing.assert_allclose(handle.position, position[sample, body], atol=1e-6)
            np.testing.assert_allclose(handle.wxyz, orientation[sample, body], atol=1e-6)


def test_bodies_are_coloured_by_speed_and_by_penetration(compared):
    shown = view(compared)
    try:
        shown.show_time(0.2)  # the balls fall at about 2 m/s
        own = [tuple(run.bodies[0].color) for run in shown.runs]
        shown.gui["colour"].value = "speed"
        shown.redraw()
        assert [tuple(run.bodies[0].color) for run in shown.runs] != own
        assert "m/s" in shown.gui["colour_legend"].content
        shown.gui["colour"].value = "penetration"
        shown.redraw()
        assert all(contacts is not None for contacts in shown.contacts)  # computed for the colours
        assert "mm" in shown.gui["colour_legend"].content
    finally:
        shown.stop()


def test_playing_moves_the_clock_at_the_chosen_speed(viewer):
    viewer.gui["speed"].value = "0.5×"
    viewer.set_playing(True)
    time.sleep(0.1)  # the run lasts 0.1 s: no wrapping round
    viewer.set_playing(False)
    assert 0.0 < viewer.gui["time"].value <= 0.5 * 0.1 + 0.03


def test_a_compare_folder_opens_its_methods_side_by_side(compared):
    shown = view(compared)
    try:
        assert [run.label for run in shown.runs] == ["bouncing_ball — penalty", "bouncing_ball — impulse"]
        left, right = (run.offset for run in shown.runs)
        assert right[0] > left[0] and left[1:].tolist() == right[1:].tolist() == [0.0, 0.0]
        assert {"/run0/label", "/run1/label", "/run0/bodies/0", "/run1/bodies/0"} <= set(shown.nodes())
        shown.show_time(0.1)  # one clock for both
        assert [shown.runs[i].arrays["time"][k] for i, k in enumerate(shown.shown)] == pytest.approx([0.1, 0.1])
    finally:
        shown.stop()


def test_a_compare_folder_shows_the_methods_of_its_comparison_not_an_earlier_ones(tmp_path):
    # issue 59: compare --methods impulse into the folder of an earlier 4-method comparison, and
    # view showed 4 pyramids for a 1-method report
    from contactlab.viewed_runs import run_folders

    for method in AVAILABLE:  # the earlier comparison's runs
        (tmp_path / method).mkdir()
        (tmp_path / method / "trajectory.h5").write_bytes(b"")
    assert run_folders(str(tmp_path)) == [str(tmp_path / method) for method in AVAILABLE]
    (tmp_path / "comparison.csv").write_text("method,steps\nimpulse,100\n", encoding="utf-8")
    assert run_folders(str(tmp_path)) == [str(tmp_path / "impulse")]


def test_viewing_a_run_returns_a_server_with_stop_and_forces_from_the_method():
    builder = ModelBuilder(gravity=(0, 0, -9.81))
    builder.add_body("sphere", radius=0.1, mass=2.0, position=(0, 0, 0.1))
    builder.add_obstacle("plane", normal=(0, 0, 1), offset=0.0)
    run = simulate(builder.finalize(), method="impulse", dt=0.002, duration=0.2)
    shown = view(run)
    assert shown.url in shown._repr_html_()
    try:
        shown.gui["forces"].value = True
        shown.show_time(0.2)
        shown.redraw()
        np.testing.assert_allclose(shown.contacts[0].forces.sum(axis=0), [0, 0, 2.0 * 9.81], rtol=1e-6, atol=1e-9)
    finally:
        shown.stop()
    assert _refused(shown.port)


@pytest.mark.parametrize("method", AVAILABLE)
def test_every_method_gives_the_forces_that_hold_a_resting_box(method):
    """StepInfo.impulses of each method, as the viewer draws them: a 2 kg box resting on the
    floor is held up by its weight, 19.62 N, spread over its four corners."""
    builder = ModelBuilder(gravity=(0, 0, -9.81))
    builder.add_body("box", half_extents=(0.1, 0.1, 0.1), mass=2.0, position=(0, 0, 0.1))
    builder.add_obstacle("plane", normal=(0, 0, 1), offset=0.0)
    model = builder.finalize()
    run = simulate(model, method=method, dt=0.002, duration=0.5)
    contacts = contacts_at(model, run.summary, run.state)
    assert len(contacts.forces) == 4
    np.testing.assert_allclose(contacts.forces.sum(axis=0), [0.0, 0.0, 2.0 * 9.81], atol=1e-3)


def _folded_cloth(self_collision):
    """A 0.1 × 0.2 m cloth (5 × 12 vertices, 4 mm thick) folded in half in the air: its upper
    half lies flat 7 mm over its lower half, 1 mm closer than its two thicknesses."""
    builder = ModelBuilder()
    builder.add_cloth(
        size=(0.1, 0.2),
        resolution=(5, 12),
        mass=0.02,
        position=(0, 0, 0.1),
        thickness=0.004,
        self_collision=self_collision,
    )
    model = builder.finalize()
    state = model.state()
    rows = state.particle_position.reshape(12, 5, 3)
    rows[6:] = rows[5::-1] + (0.0, 0.0, 0.007)
    return model, state


def test_the_contacts_shown_of_a_folded_cloth_are_its_self_contacts():
    """Nothing but the cloth is there: every contact the viewer draws is between its two layers,
    pressing them apart, most along the vertical 1 mm deep (the fold's triangles tilt the rest);
    with self-collision off there are none."""
    model, state = _folded_cloth(self_collision=True)
    shown = contacts_at(model, {}, state)
    assert len(shown.points) >= 30  # at least each vertex of the upper half over a triangle of the lower
    assert np.all((shown.points[:, 2] > 0.1) & (shown.points[:, 2] < 0.107))
    assert np.all(np.abs(shown.normals[:, 2]) > 0.9)  # vertical, tilted only by the fold's own triangles
    assert np.all(shown.depth > 0.0) and np.median(shown.depth) == pytest.approx(0.001, abs=1e-9)  # flat layers
    model, state = _folded_cloth(self_collision=False)
    assert len(contacts_at(model, {}, state).points) == 0


def test_run_view_opens_the_viewer_after_the_run(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(Viewer, "wait", Viewer.stop)  # Ctrl-C at once
    out = str(tmp_path / "ball")
    assert cli.main(["run", "bouncing_ball", "--duration", "0.05", "--out", out, "--no-plots", "--view"]) == 0
    assert "Viewer: http://127.0.0.1:" in capsys.readouterr().out
    assert cli.main(["run", "bouncing_ball", "--duration", "0.05", "--out", out, "--no-plots", "--view", "--json"]) == 0
    printed = capsys.readouterr()
    assert json.loads(printed.out)["scene"] == "bouncing_ball" and "Viewer: http://127.0.0.1:" in printed.err


def test_a_run_whose_scene_cannot_be_loaded_is_shown_without_contacts(pyramid, tmp_path):
    lone = tmp_path / "lone"
    lone.mkdir()
    shutil.copy(os.path.join(pyramid, "trajectory.h5"), lone)  # no summary.json: no scene to load
    shown = view(str(lone), pyramid)
    try:
        assert [run.model is None for run in shown.runs] == [True, False]
        shown.gui["points"].value = True
        shown.redraw()
        assert shown.contacts[0] is None and len(shown.contacts[1].points) > 0
        assert "/run0/contacts/points" not in shown.nodes() and "/run1/contacts/points" in shown.nodes()
    finally:
        shown.stop()


def test_a_folder_that_is_not_a_run_is_one_line_and_exit_code_2(tmp_path, capsys):
    assert cli.main(["view", str(tmp_path)]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and str(tmp_path) in error and "contactlab run" in error
    assert cli.main(["view", str(tmp_path / "missing")]) == 2
    assert "is not a folder" in capsys.readouterr().err
    with pytest.raises(InputError, match="found no trajectory.h5"):
        view(str(tmp_path))


@pytest.mark.parametrize("damage", ["a position not a number", "time going backwards", "no body_position"])
def test_a_damaged_run_beside_a_good_one_is_named_by_its_folder(pyramid, tmp_path, capsys, damage):
    # issue 37: `view good bad` said "error: arrays: …", naming no folder (render names it)
    import h5py

    bad = tmp_path / "bad"
    shutil.copytree(pyramid, bad)
    with h5py.File(bad / "trajectory.h5", "a") as stored:
        if damage == "a position not a number":
            stored["body_position"][1, 0, 0] = np.nan
        elif damage == "time going backwards":
            stored["time"][2] = -1.0
        else:
            del stored["body_position"]
    assert cli.main(["view", pyramid, str(bad)]) == 2
    error = capsys.readouterr().err
    assert error.startswith(f"error: {bad}: ") and error.count("\n") == 1 and "Traceback" not in error


@pytest.mark.parametrize("signum, code", [(signal.SIGTERM, 143), (signal.SIGINT, 0)])
def test_sigterm_stops_the_viewer_with_exit_code_143_and_ctrl_c_with_0(pyramid, signum, code):
    # issue 37: the viewer exited 0 on SIGTERM too; Ctrl-C is how it is closed (docs/cli.md)
    process = subprocess.Popen(
        [sys.executable, "-m", "contactlab", "view", pyramid],
        preexec_fn=interruptible,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert process.stdout.readline().startswith("Viewer: http://127.0.0.1:")
        process.send_signal(signum)
        out, err = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == code, err
    if signum == signal.SIGTERM:
        assert err == "interrupted (SIGTERM); no output written\n"
    else:
        assert err == ""


def test_a_port_in_use_is_refused(pyramid, capsys):
    with socket.socket() as taken:
        taken.bind((HOST, 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert cli.main(["view", pyramid, "--port", str(port)]) == 2
        assert f"port {port} on 127.0.0.1 is in use" in capsys.readouterr().err
        assert cli.main(["run", "bouncing_ball", "--view", "--port", str(port), "--out", "unused"]) == 2
        assert not os.path.exists("unused")  # refused before the run


# -- a real browser -----------------------------------------------------------------------


def test_the_page_draws_the_scene_and_follows_the_clock_in_headless_chromium(compared, tmp_path):
    """The compare folder's two falling balls: drawn, then lower once the clock moves on."""
    if browser.chromium() is None:
        pytest.skip("no chromium, chromium-browser or google-chrome executable on PATH")
    shown = view(compared)
    try:
        with browser.Page(shown.url) as page:
            first = page.wait_for(
                tmp_path / "first.png",
                lambda p: browser.coloured(browser.scene_part(p)) > 0.005,
                what="the bodies drawn",
            )  # WebGL in software: a few seconds
            assert shown.server.get_clients(), "the server never saw the page connect"
            shown.show_time(shown.end)  # the clock moves on
            later = page.wait_for(
                tmp_path / "later.png",
                lambda p: np.abs(browser.scene_part(p) - browser.scene_part(first)).max() > 0.2,
                seconds=20,
                what="the page following the clock",
            )
            assert browser.coloured(browser.scene_part(later)) > 0.005  # the balls are still drawn
            shown.show_time(shown.start)
            assert page.click("Play")  # a user presses Play: the clock runs
            deadline = time.monotonic() + 10
            while not (shown.playing and shown.gui["time"].value > shown.start):
                assert time.monotonic() < deadline, "pressing Play in the page did not start the clock"
                time.sleep(0.1)
            local = (shown.url, f"ws://{HOST}:{shown.port}", "data:", "blob:")
            assert page.requests and not [
                address[:100] for address in page.requests if not address.startswith(local)
            ]  # nothing fetched from the network
    finally:
        shown.stop()


def test_closing_a_page_stops_every_chromium_process_and_removes_its_profile():
    """Chromium's helpers (renderer, GPU, crash handler) can outlive its main process and keep
    writing into the profile; closing the page ends the whole process group and removes the
    profile folder (CI once failed removing it: ``Directory not empty: 'Default'``)."""
    if browser.chromium() is None:
        pytest.skip("no chromium, chromium-browser or google-chrome executable on PATH")
    for _ in range(3):  # the race showed once in a CI run: try it a few times
        page = browser.Page("data:text/html,<p>contact</p>")
        profile, group = page.profile, page.process.pid
        assert os.path.isfile(os.path.join(profile, "DevToolsActivePort"))  # Chromium used it
        page.close()
        assert not os.path.exists(profile)
        with pytest.raises(ProcessLookupError):  # no process is left in Chromium's group
            os.killpg(group, 0)
