"""Run one built-in scene with every method and write the side-by-side report.

    python3 examples/compare_methods.py [SCENE] [OUT_DIR]

The same as ``contactlab compare SCENE --out OUT_DIR``, from Python. Defaults: the sliding
block, whose stopping distance v0²/(2 μ g) every method is checked against, without videos
(add ``video=True`` for them).
"""

import sys

from contactlab.compare import compare


def main(scene="sliding_block", out="out/example-compare"):
    comparison = compare(scene, out=out, video=False, duration=1.2)
    print(comparison.summary_text)
    for row in comparison.rows:
        print(f"{row['method']:12s} {float(row['steps_per_second']):8.0f} steps/s")
    print(f"report: {comparison.report_html}")


if __name__ == "__main__":
    main(*sys.argv[1:3])
