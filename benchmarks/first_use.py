"""A new user's first hour (issue 56): a fresh virtual environment and a fresh home, then the
README's install, the first ``contactlab demo`` and five first commands, then the same five again.

    python3 benchmarks/first_use.py [--quick]

Each command's wall time is measured as the user waits for it (a fresh process, the shell's
view), with what its first line on stderr said (compiling, or stepping as Python). ``--quick``:
the install and the demo alone. Writes benchmarks/results/first_use.json (date, machine, cores,
load before and after, the numbers), which README.md's figures are checked against
(tests/test_readme.py), and prints a table for benchmarks/results.md.
"""

from __future__ import annotations

import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]
RESULT = REPOSITORY / "benchmarks" / "results" / "first_use.json"
COMMANDS = [
    ["demo"],
    ["compare", "box_pyramid", "--no-video"],
    ["run", "sphere_pile"],
    ["run", "cloth_drape"],
    ["compare", "sliding_block", "--no-video"],
]


def _machine() -> str:
    try:
        names = [line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name")]
        return f"{names[0]}, {len(names)} logical cores"
    except (OSError, IndexError):
        return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores"


def _timed(command: list[str], cwd: Path, env: dict[str, str]) -> dict:
    started = time.perf_counter()
    done = subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - started
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed ({done.returncode}):\n{done.stderr[-2000:]}")
    first = next((line for line in done.stderr.splitlines() if line.strip()), "")
    return {"command": " ".join(command[1:]), "wall_seconds": round(wall, 2), "said": first[:160]}


def main(quick: bool = False) -> dict:
    folder = Path(tempfile.mkdtemp(prefix="first_use_"))
    try:
        venv, home, work = folder / "venv", folder / "home", folder / "work"
        home.mkdir()
        work.mkdir()
        env = {key: value for key, value in os.environ.items() if not key.startswith(("NUMBA_", "CONTACTLAB_"))}
        env.update(HOME=str(home), XDG_CACHE_HOME=str(home / ".cache"), PATH=f"{venv / 'bin'}:{env['PATH']}")
        env.pop("PYTHONPATH", None)
        load_before = os.getloadavg()
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        install = _timed([str(venv / "bin" / "pip"), "install", "-q", str(REPOSITORY)], work, env)
        contactlab = str(venv / "bin" / "contactlab")
        commands = COMMANDS[:1] if quick else COMMANDS
        first = [_timed([contactlab, *command], work, env) for command in commands]
        second = [_timed([contactlab, *command], work, env) for command in commands]
        result = {
            "date": time.strftime("%Y-%m-%d"),
            "commit": subprocess.run(
                ["git", "rev-parse", "--short", "HEAD"], cwd=REPOSITORY, capture_output=True, text=True
            ).stdout.strip(),
            "machine": _machine(),
            "threads": "auto (the default)",
            "load_before": [round(value, 2) for value in load_before],
            "load_after": [round(value, 2) for value in os.getloadavg()],
            "install_seconds": install["wall_seconds"],
            "first": first,
            "second": second,
            "first_total_seconds": round(sum(entry["wall_seconds"] for entry in first), 1),
            "second_total_seconds": round(sum(entry["wall_seconds"] for entry in second), 1),
        }
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    RESULT.parent.mkdir(parents=True, exist_ok=True)
    RESULT.write_text(json.dumps(result, indent=1) + "\n")
    print(f"{result['date']}, {result['machine']}, load {result['load_before']} → {result['load_after']}")
    print(f"pip install: {result['install_seconds']} s\n")
    print("| command | first use s | second use s | first use said |\n|---|---|---|---|")
    for one, two in zip(first, second):
        print(f"| `{one['command']}` | {one['wall_seconds']} | {two['wall_seconds']} | {one['said']} |")
    ratio = result["first_total_seconds"] / result["second_total_seconds"]
    print(f"| all | {result['first_total_seconds']} | {result['second_total_seconds']} | {ratio:.1f}× |")
    return result


if __name__ == "__main__":
    main(quick="--quick" in sys.argv[1:])
