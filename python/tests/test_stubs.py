"""The type stubs (dexitac.pyi) and the module agree: every class, method,
property and function the stubs name exists, and every public name of the
module is in the stubs."""

from __future__ import annotations

import ast
from pathlib import Path

import dexitac

STUBS = Path(__file__).resolve().parents[1] / "dexitac.pyi"


def stub_tree() -> ast.Module:
    return ast.parse(STUBS.read_text())


def test_stub_names_exist_in_the_module():
    tree = stub_tree()
    missing = []
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            cls = getattr(dexitac, node.name, None)
            if cls is None:
                missing.append(node.name)
                continue
            for item in node.body:
                if isinstance(item, ast.FunctionDef) and not hasattr(cls, item.name):
                    missing.append(f"{node.name}.{item.name}")
        elif isinstance(node, ast.FunctionDef) and not hasattr(dexitac, node.name):
            missing.append(node.name)
    assert missing == []


def test_module_names_are_in_the_stubs():
    tree = stub_tree()
    named = {n.name for n in tree.body if isinstance(n, (ast.ClassDef, ast.FunctionDef))}
    named |= {n.target.id for n in tree.body if isinstance(n, ast.AnnAssign) and isinstance(n.target, ast.Name)}
    public = {n for n in dir(dexitac) if not n.startswith("_") and n != "dexitac"}
    assert public - named == set()


def test_public_classes_and_methods_have_docstrings():
    for name in ("Sensor", "Observation", "Contact", "StageTimes", "Recording", "RecordedFrame"):
        cls = getattr(dexitac, name)
        assert cls.__doc__, name
    for meth in ("from_rest", "from_rest_frames", "process", "tune", "health"):
        assert getattr(dexitac.Sensor, meth).__doc__, meth
    for fn in ("read_recording", "read_image", "tune"):
        assert getattr(dexitac, fn).__doc__, fn
