"""Progress on stderr (contactlab.progress, issue 37): a plain line every few seconds where stderr
is no terminal (a log, CI), and a terminal bar erased before the command's summary."""

import io
import re
import sys
import time

from conftest import ball_on_plane

from contactlab import cli, progress, simulate

LINE = re.compile(r"^ball \(impulse\): ([\d,]+)/200 steps \((\d+) %\) after \d+ s$")


class _Terminal(io.StringIO):
    """A stderr that says it is a terminal, keeping what was written to it."""

    def isatty(self):
        return True


def _screen_line(text):
    """What a terminal's last line shows once ``text`` is written: a carriage return goes back
    to the line's start, and what follows overwrites what was there."""
    shown, column = [], 0
    for character in text.rsplit("\n", 1)[-1]:
        if character == "\r":
            column = 0
            continue
        if column < len(shown):
            shown[column] = character
        else:
            shown.append(character)
        column += 1
    return "".join(shown)


def _ball_run():
    simulate(ball_on_plane(height=0.2), "impulse", 0.001, 0.2, progress=True, scene_name="ball")


def test_a_terminal_bar_is_erased_when_the_run_ends(monkeypatch):
    """`run box_pyramid --view` left "0/1200" on the terminal with the summary glued to it: the
    bar restarted after the first step (tqdm's reset) drew at once, and a run over within the
    bar's delay ended without erasing it."""
    terminal = _Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    _ball_run()  # shorter than BAR_DELAY: no bar, or one erased
    assert _screen_line(terminal.getvalue()).strip() == "", repr(terminal.getvalue())
    monkeypatch.setattr(progress, "BAR_DELAY", 0.0)  # a bar from the start: drawn, then erased
    terminal.seek(0)
    terminal.truncate()
    _ball_run()
    assert "ball (impulse):" in terminal.getvalue() and "/200" in terminal.getvalue()
    assert _screen_line(terminal.getvalue()).strip() == "", repr(terminal.getvalue())


def test_without_a_terminal_a_run_prints_plain_lines_every_few_seconds(monkeypatch, capsys):
    """A 54-s cloth run printed nothing to a log. Now a line every PLAIN_SECONDS (here 0: one per
    update), no carriage returns; a run shorter than PLAIN_SECONDS prints none."""
    _ball_run()
    assert capsys.readouterr().err.strip() == ""
    monkeypatch.setattr(progress, "PLAIN_SECONDS", 0.0)
    _ball_run()
    lines = [line for line in capsys.readouterr().err.splitlines() if not line.startswith("compiling")]
    assert lines and "\r" not in "".join(lines)
    counts = [int(LINE.match(line)[1].replace(",", "")) for line in lines]
    assert counts == sorted(counts) and counts[-1] == 200 and LINE.match(lines[-1])[2] == "100"


def test_a_plain_line_comes_while_nothing_finishes():
    """A cluster's poll with no job finished (cluster.run_tasks) still gives a line on time."""
    stream = io.StringIO()
    shown = progress.bar(4, "methods", "job", True, stream)
    shown.tick()
    assert stream.getvalue() == ""  # not before PLAIN_SECONDS
    shown._printed -= progress.PLAIN_SECONDS  # as if PLAIN_SECONDS had passed
    shown.tick()
    assert re.fullmatch(r"methods: 0/4 jobs \(0 %\) after \d+ s\n", stream.getvalue())
    assert progress.bar(4, "methods", "job", False, stream).tick() is None and stream.getvalue().count("\n") == 1


def test_the_command_line_shows_progress_without_a_terminal(tmp_path, monkeypatch, capsys):
    """The CLI asked for progress only when stderr was a terminal, so a log got nothing."""
    monkeypatch.setattr(progress, "PLAIN_SECONDS", 0.0)
    out = str(tmp_path / "run")
    assert cli.main(["run", "bouncing_ball", "--duration", "0.05", "--out", out, "--no-plots"]) == 0
    assert re.search(r"^bouncing_ball \(impulse\): 50/50 steps \(100 %\) after \d+ s$", capsys.readouterr().err, re.M)


def test_plain_lines_start_their_clock_again_on_restart(monkeypatch):
    # a run restarts its progress after the first step, which compiles: the first plain line then
    # comes a period after the restart, not at once (a compile of 5 s printed "1/50 steps after 5 s"
    # just before a one-line error, which then was two lines)
    import io

    from contactlab import progress

    monkeypatch.setattr(progress, "PLAIN_SECONDS", 0.2)
    stream = io.StringIO()
    lines = progress.bar(10, "run", "step", True, stream)
    time.sleep(0.25)  # the first step, compiling
    lines.restart()
    lines.update(1)
    assert stream.getvalue() == ""
    time.sleep(0.25)
    lines.update(1)
    assert stream.getvalue().startswith("run: 2/10 steps (20 %) after 0 s")
