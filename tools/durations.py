"""Record how long each test took, for the longest-first order of tests/conftest.py.

    pytest -m "slow or not slow" --junitxml=run.xml ... && python -m tools.durations run.xml

Writes tests/durations.json: {"source", "note", "seconds": {nodeid: seconds}}. The order of a run
is all it changes (never a verdict), so a stale file costs wall time, not correctness.
"""

import argparse
import json
import xml.etree.ElementTree as ET
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "tests" / "durations.json"


def nodeid(case: ET.Element) -> str:
    """pytest's node id from a junit <testcase>: classname is the dotted module path (then the
    class, for tests in a class): 'tests.test_fit' + 'test_x[p]' -> 'tests/test_fit.py::test_x[p]'.
    """
    parts = case.get("classname", "").split(".")
    modules = [p for p in parts if not p[:1].isupper()]
    classes = [p for p in parts if p[:1].isupper()]
    return "::".join(["/".join(modules) + ".py", *classes, case.get("name", "")])


def read(report: Path) -> dict[str, float]:
    cases = ET.parse(report).getroot().iter("testcase")
    return {nodeid(c): round(float(c.get("time", 0.0)), 1) for c in cases}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("report", type=Path, help="a pytest --junitxml report of a full run")
    parser.add_argument("--note", default="", help="where and how it was measured (commit, load)")
    args = parser.parse_args()
    seconds = dict(sorted(read(args.report).items(), key=lambda kv: -kv[1]))
    record = {"source": args.report.name, "note": args.note, "seconds": seconds}
    OUT.write_text(json.dumps(record, indent=1) + "\n")
    print(f"wrote {OUT} ({len(seconds)} tests, {sum(seconds.values()) / 60:.1f} min in all)")


if __name__ == "__main__":
    main()
