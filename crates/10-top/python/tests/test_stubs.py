"""The type stubs (handeye/__init__.pyi) describe the package as it is: every name and member
they declare exists at run time, every public name and member at run time is declared, and every
public callable and class has a docstring (editors show both)."""

import ast
import inspect
from pathlib import Path

import handeye

STUB = Path(handeye.__file__).with_name("__init__.pyi")


def declared():
    tree = ast.parse(STUB.read_text())
    names, members = set(), {}
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
        if isinstance(node, ast.ClassDef):
            members[node.name] = {
                n.name if isinstance(n, ast.FunctionDef) else n.target.id
                for n in node.body
                if isinstance(n, ast.FunctionDef) or (isinstance(n, ast.AnnAssign) and isinstance(n.target, ast.Name))
            }
    return names, members


def test_the_stub_declares_what_the_package_has():
    assert STUB.is_file() and STUB.with_name("py.typed").is_file()
    names, members = declared()
    public = set(handeye.__all__) | {"__version__"}
    assert public - {"__version__"} <= names, public - names
    for name in names:
        if name.startswith("_"):
            continue
        assert hasattr(handeye, name), f"the stub declares handeye.{name}, which does not exist"
    for cls, declared_members in members.items():
        runtime = getattr(handeye, cls)
        for member in declared_members - {"__init__"}:
            assert hasattr(runtime, member), f"the stub declares {cls}.{member}, which does not exist"
        if issubclass(runtime, BaseException):  # the errors and CalibrationWarning: inherited members
            continue
        actual = {m for m in dir(runtime) if not m.startswith("_")}
        assert actual <= declared_members, f"{cls} has members the stub misses: {actual - declared_members}"


def test_every_public_callable_has_a_docstring():
    for name in handeye.__all__:
        obj = getattr(handeye, name)
        if callable(obj):
            assert inspect.getdoc(obj), f"handeye.{name} has no docstring"
        if inspect.isclass(obj) and not issubclass(obj, BaseException):
            for member in dir(obj):
                if not member.startswith("_"):
                    assert inspect.getdoc(getattr(obj, member)), f"handeye.{name}.{member} has no docstring"
