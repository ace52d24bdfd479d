"""The tracker's options are defined once, in the library's table (roitrack_core's `tracker_options!`): the keyword
arguments of `Tracker` and `track` and their stubs follow it, so an option added to the table and not to the stubs
fails here (and in stubtest). The command line is checked by crates/roitrack-cli/tests/tracker_options.rs."""

import ast
import inspect
from pathlib import Path
from typing import Any

import roitrack
from roitrack import _roitrack

STUBS = Path(__file__).resolve().parents[1] / "python" / "roitrack" / "_roitrack.pyi"

# The stub's annotation of a Rust type, by shape.
PYTHON_TYPES = {"f64": "float", "usize": "int"}


def table() -> list[tuple[str, str, Any]]:
    """(name, annotation the stubs give, default) for each entry of the table."""
    rows = []
    for name, shape, default, rust_type in _roitrack._tracker_options():
        base = "str" if shape.endswith("named") else PYTHON_TYPES[rust_type]
        annotation = f"Optional[{base}]" if shape.startswith("optional") else base
        rows.append((name, annotation, ast.literal_eval(default)))
    return rows


def runtime_options(function: Any, fixed: list[str]) -> list[tuple[str, Any]]:
    """(name, default) of the parameters after `fixed` in the compiled signature."""
    parameters = list(inspect.signature(function).parameters.values())
    assert [p.name for p in parameters[: len(fixed)]] == fixed
    return [(p.name, p.default) for p in parameters[len(fixed) :]]


def stub_options(node: ast.FunctionDef, fixed: list[str]) -> list[tuple[str, str, Any]]:
    """(name, annotation, default) of the parameters after `fixed` in a stub."""
    args = node.args.args
    assert [a.arg for a in args[: len(fixed)]] == fixed
    defaults = [None] * (len(args) - len(node.args.defaults)) + list(node.args.defaults)
    return [
        (a.arg, ast.unparse(a.annotation) if a.annotation else "", ast.literal_eval(d) if d is not None else None)
        for a, d in zip(args[len(fixed) :], defaults[len(fixed) :])
    ]


def stub_functions() -> dict[str, ast.FunctionDef]:
    tree = ast.parse(STUBS.read_text())
    found = {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            found[node.name] = node
        if isinstance(node, ast.ClassDef) and node.name == "Tracker":
            for item in node.body:
                if isinstance(item, ast.FunctionDef) and item.name == "__new__":
                    found["Tracker.__new__"] = item
    return found


def test_the_table_lists_the_tracker_options() -> None:
    names = [name for name, _, _ in table()]
    assert names[:3] == ["estimator", "every", "gain"]
    assert len(names) == len(set(names)) >= 14


def test_the_signatures_of_tracker_and_track_are_the_table() -> None:
    expected = [(name, default) for name, _, default in table()]
    assert runtime_options(roitrack.track, ["camera", "target", "measurements"]) == expected
    assert runtime_options(roitrack.Tracker, ["camera", "target"]) == expected


def test_the_stubs_of_tracker_and_track_are_the_table() -> None:
    stubs = stub_functions()
    assert stub_options(stubs["Tracker.__new__"], ["cls", "camera", "target"]) == table()
    assert stub_options(stubs["track"], ["camera", "target", "measurements"]) == table()


def test_every_default_of_the_table_builds_a_tracker() -> None:
    sim = roitrack.simulate("static", seed=1)
    defaults = {name: default for name, _, default in table()}
    tracker = roitrack.Tracker(sim["camera"], sim["target"], **defaults)
    assert tracker.measurements == 0
