"""The README's Python example runs as written."""

import re
from pathlib import Path


def test_readme_python_example_runs(capsys):
    text = (Path(__file__).parent.parent / "README.md").read_text()
    example = re.search(r"## Python API\n\n```python\n(.*?)```", text, re.S).group(1)
    assert len(example.strip().splitlines()) <= 11
    exec(compile(example, "README.md", "exec"), {})
    printed = capsys.readouterr().out.split()
    assert float(printed[0]) < 1e-3 and printed[-1] == "3)"


def test_readme_and_docs_links_point_at_files_that_exist():
    root = Path(__file__).parent.parent
    for page in [root / "README.md", *sorted((root / "docs").rglob("*.md"))]:
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", page.read_text()):
            if "://" in target:
                continue
            assert (page.parent / target).exists(), f"{page.relative_to(root)} links to missing {target}"


def test_the_figures_script_regenerates_every_picture_the_docs_show(tmp_path):
    """docs/make_figures.py (short runs) writes every file under docs/figures/ that a page shows."""
    import subprocess
    import sys

    root = Path(__file__).parent.parent
    result = subprocess.run(
        [sys.executable, str(root / "docs" / "make_figures.py"), "--quick", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert result.returncode == 0, result.stderr
    shown = set()
    for page in [root / "README.md", *sorted((root / "docs").rglob("*.md"))]:
        for target in re.findall(r"\]\(([^)\s]*figures/[^)\s]+)\)", page.read_text()):
            shown.add((page.parent / target).resolve().relative_to((root / "docs" / "figures").resolve()))
    assert shown, "no page shows a figure"
    from contactlab.browser import chromium

    for figure in shown:
        if figure.name == "viewer.png" and chromium() is None:
            print("viewer.png not checked: it is drawn in headless Chromium, not on PATH")
            continue
        assert (tmp_path / figure).is_file(), f"the script does not make {figure}"


def _cells(line):
    return [cell.strip() for cell in line.strip().strip("|").split("|")]


def _spec_table_rows():
    """(SPEC items, where, proved by) of each row of the README's table from SPEC items to code."""
    text = (Path(__file__).parent.parent / "README.md").read_text()
    table = text.split("## Features by specification item", 1)[1].split("\n\n", 2)[1]
    lines = [line for line in table.splitlines() if line.startswith("|")][2:]
    return [_cells(line) for line in lines]


def _defined(path, name):
    """Whether the Python file ``path`` defines ``name`` (a function, class or module-level name);
    a trailing * matches any name with that prefix."""
    source = path.read_text()
    pattern = re.escape(name[:-1]) + r"\w*" if name.endswith("*") else re.escape(name) + r"\b"
    return re.search(rf"^(?:@njit[^\n]*\n)?\s*(?:def|class)\s+{pattern}|^{pattern}\s*=", source, re.M) is not None


def test_every_code_name_in_the_readme_spec_table_exists():
    """The table's "where" column names files of src/contactlab/ and, in parentheses, what they
    define; scene-file option tables ([method.NAME]) and their options; its "proved by"
    column names tests (file.py::test, later tests of the same file by name alone)."""
    from dataclasses import fields

    from contactlab import methods

    root = Path(__file__).parent.parent
    package, tests = root / "src" / "contactlab", root / "tests"
    rows = _spec_table_rows()
    assert len(rows) > 20
    missing = []
    for item, where, proved in rows:
        module, options = None, None
        for part in re.findall(r"\(([^)]*)\)|`([^`]+)`", where):
            names, token = part
            if names:  # names the last file defines
                for name in re.findall(r"`([^`]+)`", names):
                    if module is None or not _defined(module, name):
                        missing.append(f"{item}: {name} in {module}")
                continue
            if token.endswith(".py") or token.endswith("/"):
                module, options = package / token, None
                if not module.exists():
                    missing.append(f"{item}: {token}")
                module = module if token.endswith(".py") else None
            elif token.startswith("[method."):
                options = {f.name for f in fields(methods.get(token[len("[method.") :].split("]")[0]).Options)}
                option = token.split("]", 1)[1].strip()
                if option and option not in options:
                    missing.append(f"{item}: {token}")
            elif options is not None:
                if token not in options:
                    missing.append(f"{item}: option {token}")
            else:
                missing.append(f"{item}: {token} (not a file, name or option)")
        test_file = None
        for token in re.findall(r"`([^`]+)`", proved):
            file_name, _, name = token.partition("::")
            if file_name.endswith(".py"):
                test_file = tests / file_name
                if not test_file.exists():
                    missing.append(f"{item}: {file_name}")
                    continue
            else:
                name = token
            if name and (test_file is None or not _defined(test_file, name)):
                missing.append(f"{item}: {name} in {test_file}")
    assert not missing, missing


def test_the_readmes_first_use_figures_are_the_benchmarks():
    """The first demo's and the first five commands' times in README.md are those of
    benchmarks/results/first_use.json (benchmarks/first_use.py), as it rounds them."""
    import json

    root = Path(__file__).parent.parent
    result = json.loads((root / "benchmarks" / "results" / "first_use.json").read_text())
    text = " ".join((root / "README.md").read_text().split())
    demo = re.search(r"the first `contactlab demo` in a fresh environment and home takes ([\d.]+) s", text)
    assert demo and float(demo.group(1)) == round(result["first"][0]["wall_seconds"], 1)
    assert f"({result['date']}, {result['machine'].split(',')[0]}" in text
    compare = re.search(
        r"compiles its kernels first: ([\d.]+) s on 2 cores with `--no-video`, ([\d.]+) s the second", text
    )
    times = {run["command"]: run["wall_seconds"] for run in result["first"]}
    again = {run["command"]: run["wall_seconds"] for run in result["second"]}
    pyramid = "compare box_pyramid --no-video"
    assert compare and (float(compare.group(1)), float(compare.group(2))) == (
        round(times[pyramid]),
        round(again[pyramid], 1),
    )
    install = re.search(r"`pip install \.` took ([\d.]+) s", text)
    assert install and float(install.group(1)) == round(result["install_seconds"])
    if len(result["first"]) == 5:
        five = re.search(r"the five first commands of issue 56 took ([\d.]+) s, against ([\d.]+) s", text)
        assert five and (float(five.group(1)), float(five.group(2))) == (
            round(result["first_total_seconds"]),
            round(result["second_total_seconds"]),
        )


def _readme_text():
    """README.md with its lines joined by single spaces (a figure may be wrapped anywhere)."""
    return " ".join((Path(__file__).parent.parent / "README.md").read_text().split())


def test_the_readmes_figures_against_the_peers_are_the_benchmarks():
    """Every figure of the README's paragraph on the peers is benchmarks/results/results.json's
    (benchmarks/peers.py), rounded as the text has it, with that file's date, machine and load."""
    import json

    root = Path(__file__).parent.parent
    result = json.loads((root / "benchmarks" / "results" / "results.json").read_text())
    runs, text = result["runs"], _readme_text()

    def rate(key):
        return runs[key]["steps_per_second"]

    def ratio(key, peer):
        return rate(key) / rate(peer)

    loads = [
        load
        for key in runs
        if key.split("/")[0] in ("pyramid", "pile1000", "pile4000", "ball", "manyruns")
        for load in runs[key]["load"]
    ]
    assert f"({result['machine']['date']}, {result['machine']['cpu'].split('(')[0]}" in text
    assert f"load {min(loads):.1f}–{max(loads):.1f}: benchmarks/results/results.json" in text
    expected = {
        "pyramid 4.2× as fast as pybullet under constraints": ratio(
            "pyramid/contactlab-constraints", "pyramid/pybullet"
        ),
        "and 4.3× under impulses": ratio("pyramid/contactlab-impulse", "pyramid/pybullet"),
        "0.97× under penalty": ratio("pyramid/contactlab-penalty", "pyramid/pybullet"),
        "and 1.09× under projection": ratio("pyramid/contactlab-projection", "pyramid/pybullet"),
        "(4.56 sweeps a step": runs["pyramid/contactlab-impulse"]["sweeps_per_step"],
        "every box within 0.07 mm": 1e3 * runs["pyramid/contactlab-impulse"]["drift"],
        "a pybullet box moved 234 mm": 1e3 * runs["pyramid/pybullet"]["drift"],
        "sphere piles 2.1×": ratio("pile1000/contactlab-constraints", "pile1000/pybullet"),
        "and 3.6× as fast under constraints": ratio("pile4000/contactlab-constraints", "pile4000/pybullet"),
        "penetration (0.53": 1e3 * runs["pile1000/contactlab-constraints"]["max_penetration"],
        "and 1.1 mm against": 1e3 * runs["pile4000/contactlab-constraints"]["max_penetration"],
        "against 9.5": 1e3 * runs["pile1000/pybullet"]["max_penetration"],
        "and 18.4 mm)": 1e3 * runs["pile4000/pybullet"]["max_penetration"],
        "about 407,000 steps/s": rate("ball/contactlab-impulse"),
        "0.77× pybullet": ratio("ball/contactlab-impulse", "ball/pybullet"),
        "0.87× MuJoCo": ratio("ball/contactlab-impulse", "ball/mujoco"),
        "at 0.55× MuJoCo's throughput": runs["manyruns/mujoco"]["ms_per_run"]
        / runs["manyruns/contactlab"]["defaults"]["ms_per_run"],
    }
    for phrase, value in expected.items():
        assert phrase in text, phrase
        shown = re.search(r"\d[\d,]*(?:\.\d+)?", phrase).group(0)
        digits = len(shown.split(".")[1]) if "." in shown else -3 if shown.endswith(",000") else 0
        assert float(shown.replace(",", "")) == round(value, digits), (phrase, value)


def _table_rows(path):
    """The rows of the first Markdown table of ``path``, as lists of cell texts (the header and
    the rule left out)."""
    lines = [line for line in path.read_text().splitlines() if line.startswith("|")]
    return [_cells(line) for line in lines[2:]]


def test_the_docs_figures_on_cloth_self_contact_are_the_benchmarks():
    """docs/collision.md's cost of cloth self-contact is benchmarks/results/cloth_self.md's
    (benchmarks/cloth_self.py): its ratios, its self-contacts, its date and load."""
    root = Path(__file__).parent.parent
    results = root / "benchmarks" / "results" / "cloth_self.md"
    rows = {row[0]: row for row in _table_rows(results)}
    drape, fold = rows["cloth_drape, self_collision = true"], rows["folding 64 × 64, self_collision = true"]
    date, load = re.search(r"(\d{4}-\d\d-\d\d), .*load average ([\d.]+)", results.read_text()).groups()
    text = " ".join((root / "docs" / "collision.md").read_text().split())
    assert f"cloth_self.md`, {date}, 2 cores, load {float(load):.1f})" in text
    assert f"a step takes {drape[3]} as long as without self-contact" in text
    contacts = f"{round(int(fold[5]), -2):,}".replace(",", " ")  # 2 300, as the page writes thousands
    assert f"folding onto itself, {fold[3]}, with some {contacts} self-contacts" in text


def test_the_docs_sweep_speedup_is_the_benchmark():
    """docs/sweep.md's table of a local cluster against the cells in series is
    benchmarks/results/sweep_speedup.md's (benchmarks/sweep_speedup.py), with its date, machine
    and loads, and the study size from which the cluster pays is the file's and the one
    ``cluster.LOCAL_CLUSTER_PAYS_FROM`` holds (issue 59)."""
    from contactlab import cluster

    root = Path(__file__).parent.parent
    results = (root / "benchmarks" / "results" / "sweep_speedup.md").read_text()
    rows = [
        row for row in _table_rows(root / "benchmarks" / "results" / "sweep_speedup.md") if row[0].startswith("idle")
    ]
    date, cpu = re.search(r"on (\d{4}-\d\d-\d\d): ([^,]+), 2 cores", results).groups()
    loads = [float(re.search(r"load ([\d.]+) at start", row[0]).group(1)) for row in rows]
    pays = re.search(
        r"Idle: the sweep, its cluster's start counted, pays from about (\d+) s of cells in series", results
    )
    text = " ".join((root / "docs" / "sweep.md").read_text().split())
    assert (
        f"Its committed run ({date}, {cpu}, 2 cores, load {min(loads):.1f}–{max(loads):.1f} at the studies' starts)"
        in text
    )
    for row in rows:
        assert f"| {row[2]} | {row[3]} s | {row[6]} s | {row[7]} |" in text, row
    assert f"A local cluster on 2 cores pays from about {pays.group(1)} s of cells in series" in text
    assert cluster.LOCAL_CLUSTER_PAYS_FROM == float(pays.group(1))


def _table(text, header):
    """{first cell: cells} of the Markdown table of ``text`` that starts with the line ``header``."""
    lines = text.splitlines()
    start = lines.index(header) + 2
    rows = {}
    for line in lines[start:]:
        if not line.startswith("|"):
            break
        cells = _cells(line)
        rows[cells[0]] = cells
    return rows


def test_the_lcp_pages_figures_are_the_benchmarks():
    """docs/lcp.md's solver figures are those of their results files: red-black against pgs
    (results.json's lcp runs), newton against nsgs on the FCLIB files (fclib_newton.md) and
    newton on every readable problem (fclib_newton_siconos.md), tables and sums."""
    import json

    root = Path(__file__).parent.parent
    results = root / "benchmarks" / "results"
    page = (root / "docs" / "lcp.md").read_text()
    text = " ".join(page.split())
    lcp = json.loads((results / "results.json").read_text())["runs"]
    pgs = lcp["lcp/pgs"]["seconds"]
    assert f"converged {pgs / lcp['lcp/redblack']['seconds']:.2f}× as fast as `pgs` on 2 cores" in text
    assert f"solved that pile's LCP {pgs / lcp['lcp/redblack_blocks']['seconds']:.2f}× as fast as `pgs`" in text
    sweeps = [lcp[f"lcp/{name}"]["sweeps"] for name in ("pgs", "redblack_blocks", "redblack")]
    assert f"({sweeps[1]} against {sweeps[0]} on the 4000-sphere pile; `redblack`'s order {sweeps[2]} there)" in text

    newton = _table((results / "fclib_newton.md").read_text(), _header(results / "fclib_newton.md", "| file | nc |"))
    shown = _table(page, "| file | nc | newton steps | newton error | newton ms | nsgs sweeps | nsgs error | nsgs ms |")
    assert len(shown) == 15 and all(cells == newton[name][:8] for name, cells in shown.items())
    together = [round(sum(float(cells[column]) for cells in shown.values())) for column in (4, 7)]
    assert f"in {together[0]} ms together (nsgs: {together[1]} ms)" in text

    every = _table(
        (results / "fclib_newton_siconos.md").read_text(),
        "| file | nc | newton iterations | newton error | newton ms |",
    )
    shown = _table(page, "| problem | contacts | in data/fclib | method | iterations | time (ms) | error reached |")
    assert {name: [c[1], c[4], c[5], c[6]] for name, c in shown.items()} == {
        name: [c[1], c[2], c[4], c[3]] for name, c in every.items()
    }
    slowest = sorted(every.values(), key=lambda cells: -float(cells[4]))[:2]
    total = sum(float(cells[4]) for cells in every.values()) / 1e3
    assert (
        f"the slowest in {float(slowest[0][4]) / 1e3:.2f} s ({slowest[0][0].split('-')[0]}, {slowest[0][2]} steps"
        in text
    )
    assert f"and {float(slowest[1][4]) / 1e3:.2f} s ({slowest[1][0].split('.')[0]}, {slowest[1][2]} steps)" in text
    assert f"{total:.1f} s for all {len(every)}." in text


def _header(path, start):
    """The first line of ``path`` that starts with ``start`` (a table's header)."""
    return next(line for line in path.read_text().splitlines() if line.startswith(start))


def _page_text(*parts):
    """A page of docs/ with its lines joined by single spaces (a figure may be wrapped anywhere)."""
    return " ".join(Path(__file__).parent.parent.joinpath("docs", *parts).read_text().split())


def test_the_methods_pages_figures_are_the_benchmarks():
    """docs/methods/*.md quote benchmarks/results/results.json (benchmarks/peers.py) for the
    20-level pyramid under penalty and impulse, the 64 × 64 cloth under constraints and
    redblack_blocks against pgs, rounded as the pages have them, with the file's date, machine
    and loads (issue 59)."""
    import json

    root = Path(__file__).parent.parent
    result = json.loads((root / "benchmarks" / "results" / "results.json").read_text())
    runs, date = result["runs"], result["machine"]["date"]
    cpu = result["machine"]["cpu"].replace("(R)", "").replace(" Processor", "")  # Intel Xeon
    assert result["machine"]["cores"] == 2
    penalty, pybullet = runs["pyramid/contactlab-penalty"], runs["pyramid/pybullet"]
    loads = penalty["load"] + pybullet["load"]
    text = _page_text("methods", "penalty.md")
    assert (
        f"({date}, {cpu}, 2 cores, load {min(loads):.2f}–{max(loads):.2f}: `benchmarks/results/results.json`," in text
    )
    assert (
        f"the pyramid under penalty steps at {penalty['steps_per_second']:.0f} steps/s against pybullet's "
        f"{pybullet['steps_per_second']:.0f}, every box within {1e3 * penalty['drift']:.1f} mm." in text
    )
    impulse = runs["pyramid/contactlab-impulse"]
    text = _page_text("methods", "impulse.md")
    assert (
        f"every box of that pyramid stays within {1e3 * impulse['drift']:.2f} mm over 5 s at "
        f"{impulse['sweeps_per_step']:.2f} sweeps a step ({date}, {cpu}, 2 cores, load "
        f"{impulse['load'][0]:.2f}: `benchmarks/results/results.json`, `pyramid/contactlab-impulse`)" in text
    )
    cloth = runs["cloth64/contactlab-constraints"]
    text = _page_text("methods", "constraints.md")
    assert (
        f"({date}, {cpu}, 2 cores, load {cloth['load'][0]:.1f}: `benchmarks/results/results.json`, "
        f"`cloth64/contactlab-constraints`) a 64 × 64 cloth steps at {cloth['steps_per_second']:.2f} steps/s" in text
    )
    assert cloth["vertices"] == 64 * 64
    blocks = runs["lcp/pgs"]["seconds"] / runs["lcp/redblack_blocks"]["seconds"]
    assert f"the assembled LCP: {blocks:.2f}× `pgs` on the 4000-sphere pile" in text


def _sci(value):
    """``value`` as the pages write it: two digits, the exponent without its padding (3.5e-2)."""
    mantissa, exponent = f"{value:.1e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def _thousands(count):
    """``count`` with thousands set apart by a space, as the pages write them (3 197)."""
    return f"{count:,}".replace(",", " ")


def test_the_constraints_pages_convergence_figures_are_the_benchmark():
    """docs/methods/constraints.md's sweeps, changes and errors on the settled pile and pyramid
    are benchmarks/results/convergence.json's (benchmarks/convergence.py), as the page rounds them."""
    import json

    import numpy as np

    root = Path(__file__).parent.parent
    result = json.loads((root / "benchmarks" / "results" / "convergence.json").read_text())
    pile, pyramid = result["pile1000"], result["pyramid20"]
    text = _page_text("methods", "constraints.md")
    methods_order = next(name for name in pile["curves"] if name.startswith("methods' order"))
    change = np.array(pile["curves"][methods_order]["change"])
    facts = pile["facts"]
    assert f"On the pile's step ({_thousands(facts['contacts'])} contacts, none new)" in text
    assert facts["new"] == 0
    assert f"the first sweep changes a contact velocity by {_sci(change[0])} m/s" in text
    assert (
        f"After 10 sweeps the change is {_sci(change[9])}, after 50 it is {_sci(change[49])}, "
        f"after 100 it is {_sci(change[99])} and after 150 it is {_sci(change[149])} m/s" in text
    )
    fast, slow = (100 * (1 - (change[b - 1] / change[a - 1]) ** (1 / (b - a))) for a, b in ((50, 100), (100, 150)))
    assert f"by about {fast:.1f} % a sweep between sweeps 50 and 100, and by only {slow:.0f} % between" in text
    assert f"({facts['mean_sweeps_while_settling']:.1f} over the 1.5 s settle" in text
    assert f"Even a tolerance of 1e-5 m/s costs {np.argmax(change < 1e-5) + 1} sweeps here" in text
    assert f"still costs {np.argmax(change < 1e-5) + 1} sweeps on this step" in text
    colours = next(name for name in pile["curves"] if name.startswith("coloured"))
    assert f"a {colours.split('(')[1].split()[0]}-colour graph colouring" in text

    def stop(curve):
        return int(np.argmax(np.array(curve["change"]) <= 1e-7)) + 1

    top = stop(pyramid["curves"][methods_order])
    orders = [name for name in pyramid["curves"] if name.startswith(("bottom", "collision", "random", "coloured"))]
    assert len(orders) == 4
    others = sorted(stop(pyramid["curves"][name]) for name in orders)
    assert stop(pyramid["curves"]["top down"]) == top
    assert f"top down reaches the tolerance in {top} sweeps, against {others[0]}–{others[-1]} for" in text
    lowest = min(min(curve["error"]) for curve in pyramid["curves"].values())
    assert round(lowest, 5) == 4e-5  # "no solver drives the natural-map error below about 4e-5"
    newton, error = pile["curves"]["newton"], np.array(pile["curves"][methods_order]["error"])
    steps = dict(zip(newton["sweeps"], newton["error"]))
    assert (
        f"error of {_sci(steps[1])} after 1 and 2 steps and {_sci(steps[4])} after 4. The sweeps reach those errors "
        f"in {np.argmax(error <= steps[1]) + 1} and {np.argmax(error <= steps[4]) + 1} sweeps" in text
    )
    assert steps[2] == steps[1] and f"a {_thousands(3 * facts['contacts'])}-row matrix" in text
    top_percent, every = facts["top_percent"], facts["all_contacts"]
    assert (
        f"have a median height of {top_percent['median_height']:.2f} m, against {every['median_height']:.2f} m" in text
    )
    sliding = facts["change_by_sliding"]
    assert f"a median change {sliding['sliding_median'] / sliding['sticking_median']:.1f} times the sticking" in text
    assert f"There are only {every['sliding']} of them ({top_percent['sliding']} in the top 1 %)" in text


def test_the_peers_pages_figures_are_the_benchmarks():
    """docs/peers.md's stopping distances on sliding_block, its bounce ratios on bouncing_ball,
    the example report's verdicts and MuJoCo's note are benchmarks/results/results.json's
    (`benchmarks/peers.py --only scenes`), with its date, machine and load (issue 59)."""
    import json

    root = Path(__file__).parent.parent
    result = json.loads((root / "benchmarks" / "results" / "results.json").read_text())
    runs, date = result["runs"], result["machine"]["date"]
    cpu = result["machine"]["cpu"].replace("(R)", "").replace(" Processor", "")  # Intel Xeon
    page = (root / "docs" / "peers.md").read_text()
    text = " ".join(page.split())

    def check(run, quantity):
        return next(c for c in runs[run]["checks"] if c["quantity"] == quantity)

    mujoco, pybullet = (check(f"builtin-sliding_block/{peer}", "stopping distance") for peer in ("mujoco", "pybullet"))
    assert (
        f"MuJoCo stops the block at {mujoco['measured']:.3f} m, pybullet at {pybullet['measured']:.3f} m (closed form "
        f"{mujoco['expected']:.3f} m; {date}, {cpu}, 2 cores: `benchmarks/results/results.json`, "
        "`builtin-sliding_block/…`)" in text
    )
    ball = [f"builtin-bouncing_ball/{engine}" for engine in ("mujoco", "pybullet", "contactlab-impulse")]
    loads = {load for run in ball for load in runs[run]["load"]}
    assert len(loads) == 1
    assert f"({date}, {cpu}, 2 cores, load {loads.pop():.1f}: `benchmarks/results/results.json`, " in text

    def returned(run, bounce):
        """The share of its speed the ball keeps at a bounce: √ of the ratio of its heights (ε = 0.8)."""
        first = check(run, "rebound 1 apex")
        heights = [first["expected"] / 0.8**2, first["measured"], check(run, "rebound 2 apex")["measured"]]
        return (heights[bounce] / heights[bounce - 1]) ** 0.5

    assert f"MuJoCo's first bounce returns {returned(ball[0], 1):.2f} of the speed where ε = 0.8" in text
    assert f"pybullet's first bounce returns {returned(ball[1], 1):.2f}, its second {returned(ball[1], 2):.2f}" in text
    for run, name in zip(ball, ("mujoco", "pybullet", "impulse")):
        assert f"| {name} | ok | {runs[run]['expectations']} |" in page, name
    assert f"- mujoco: {runs[ball[0]]['engine_notes'][0]}" in page


def test_the_lcp_pages_counts_are_the_benchmarks():
    """docs/lcp.md's counts outside its tables are its results files': redblack's colors on the
    4000-sphere pile (results.json), apgd's steps to 1e-8, nsgs' error on the rock pile after
    10 000 sweeps and newton's steps there (fclib_newton.md) (issue 59)."""
    import json

    root = Path(__file__).parent.parent
    results = root / "benchmarks" / "results"
    text = " ".join((root / "docs" / "lcp.md").read_text().split())
    colors = json.loads((results / "results.json").read_text())["runs"]["lcp/redblack"]["colors"]
    assert f"one per color (`redblack`'s {colors} on the 4000-sphere pile)" in text
    rows = _table((results / "fclib_newton.md").read_text(), _header(results / "fclib_newton.md", "| file | nc |"))

    def apgd(name):
        file = next(cells for key, cells in rows.items() if key.startswith(name))
        assert "no" not in file[9]  # solved
        return file[8]

    assert (
        f"At tol 1e-8 with 10 000 steps apgd takes {apgd('Capsules-i100')} steps on Capsules-i100, "
        f"{apgd('Capsules-i101')} on Capsules-i101, {apgd('Capsules-i125')} on Capsules-i125, "
        f"{apgd('BoxesStack1')} on BoxesStack1 and {apgd('local_problem_test')} on local_problem_test" in text
    )
    shown = _table(
        (root / "docs" / "lcp.md").read_text(),
        "| file | nc | newton steps | newton error | newton ms | nsgs sweeps | nsgs error | nsgs ms |",
    )
    solved = sum("no" not in rows[name][6] for name in shown)
    assert all("no" not in rows[name][3] for name in shown)
    assert f"newton solved all {len(shown)} to 1e-8 (nsgs {solved}, its Capsules-i101 error within rounding" in text
    pile = rows["RockPile_tob1.dat"]
    assert pile[5] == "10000" and f"nsgs gets to {pile[6].split()[0].replace('e-05', 'e-5')} in 10 000 sweeps" in text
    assert float(pile[3]) <= 1e-8 and f"the one kept, solves it in {pile[2]} steps" in text
