"""Every script in examples/ runs from a fresh folder and prints what its docstring promises."""

import os
import re
import subprocess
import sys

import pytest

EXAMPLES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "examples")


def run_example(name, *args, cwd):
    result = subprocess.run(
        [sys.executable, os.path.join(EXAMPLES, name), *args], cwd=cwd, capture_output=True, text=True, timeout=600
    )
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_every_example_is_tested():
    scripts = {name for name in os.listdir(EXAMPLES) if name.endswith(".py")}
    tested = {"bouncing_ball.py", "compare_methods.py", "lcp_column.py", "cloth_export.py"}
    assert scripts == tested


def test_bouncing_ball_rebounds(tmp_path):
    out = run_example("bouncing_ball.py", cwd=tmp_path)
    heights = {line.split()[0]: [float(h) for h in re.findall(r"([\d.]+) m\b", line)] for line in out.splitlines()[1:]}
    for method in ("impulse", "constraints"):
        assert heights[method] == pytest.approx([0.64, 0.4096], rel=1e-3)
    assert heights["penalty"] == pytest.approx([0.64, 0.4096], rel=0.03)
    assert "does not bounce" in out.splitlines()[2]  # projection


def test_lcp_column_three_solvers_agree_with_the_weights(tmp_path):
    out = run_example("lcp_column.py", cwd=tmp_path)
    lines = out.splitlines()
    assert len(lines) == 3
    for line in lines:
        assert "converged=True" in line
        assert float(line.rsplit("error ", 1)[1].split()[0]) < 1e-8


def test_compare_methods_writes_the_report(tmp_path):
    out = run_example("compare_methods.py", "sliding_block", "report", cwd=tmp_path)
    assert (tmp_path / "report" / "report.html").is_file()
    assert (tmp_path / "report" / "comparison.csv").is_file()
    for method in ("penalty", "projection", "impulse", "constraints"):
        assert re.search(rf"^{method}\s+\d+ steps/s$", out, re.M)


def test_cloth_export_matches_the_trajectory(tmp_path):
    out = run_example("cloth_export.py", "cloth", cwd=tmp_path)
    assert (tmp_path / "cloth" / "run.usd").is_file()
    frames = sorted(os.listdir(tmp_path / "cloth" / "frames"))
    assert frames[0] == "frame_00000.obj" and len(frames) > 5
    gap_mm = float(re.search(r"is ([\d.e+-]+) mm from", out).group(1))
    assert gap_mm < 1e-3  # USD points are single precision: about 1e-7 m
