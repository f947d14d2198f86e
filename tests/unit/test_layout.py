"""The package layout's contracts: public surfaces, one error hierarchy, reason codes in one module."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

from fusiond import errors, reasons

PACKAGE = Path(__file__).resolve().parents[2] / "fusiond"


@pytest.mark.parametrize("name", ["fusiond.core", "fusiond.transport", "fusiond.replay", "fusiond.estimator"])
def test_each_package_declares_a_public_surface_that_resolves(name):
    pkg = importlib.import_module(name)
    assert pkg.__all__ and len(set(pkg.__all__)) == len(pkg.__all__)
    for n in pkg.__all__:
        assert getattr(pkg, n) is not None, n
    with pytest.raises(AttributeError):
        getattr(pkg, "no_such_name")


def test_every_error_is_a_fusiond_error_and_old_names_are_the_same_classes():
    from fusiond.config import ConfigError
    from fusiond.replay.bag import BagError
    from fusiond.codecs import DecodeError
    from fusiond.transport.session import SessionError

    for name in errors.__all__:
        assert issubclass(getattr(errors, name), errors.FusiondError), name
    assert ConfigError is errors.ConfigError and issubclass(ConfigError, ValueError)
    assert BagError is errors.BagError and issubclass(BagError, ValueError)
    assert issubclass(BagError, errors.ReplayError)
    assert SessionError is errors.SessionError and issubclass(SessionError, RuntimeError)
    assert issubclass(SessionError, errors.TransportError)
    assert issubclass(DecodeError, errors.CodecError) and issubclass(DecodeError, ValueError)


def test_an_estimate_before_any_sample_is_a_core_error():
    from fusiond.config import loads
    from fusiond.core import FusionCore

    core = FusionCore(loads('[[sensors]]\nname = "wheel"\nkind = "odom"\nkey = "odom"\n'))
    with pytest.raises(errors.CoreError, match="no sample has been fused yet"):
        core.estimate()
    with pytest.raises(errors.CoreError):
        core.pose()


def test_reason_codes_are_unique_and_each_has_a_meaning():
    codes = [v for k, v in vars(reasons).items() if k.isupper() and isinstance(v, str)]
    assert len(codes) == len(set(codes)) == len(reasons.MEANINGS)
    assert set(codes) == set(reasons.ALL)
    for code, meaning in reasons.MEANINGS.items():
        assert code == code.lower() and " " not in code
        assert meaning and "\n" not in meaning


def test_the_codecs_reasons_are_listed():
    from fusiond import codecs

    assert set(codecs.REASONS) <= set(reasons.ALL)


_REASON_CALLS = {"Rejected": 0, "_drop": 1, "on_dropped": 1}  # callee -> position of the reason argument


def test_no_reason_code_is_a_literal_outside_reasons_py():
    """Drops and rejections name their reason through fusiond.reasons, so that module is the whole list."""
    literal: list[str] = []
    for path in PACKAGE.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if not isinstance(node, ast.Call):
                continue
            f = node.func
            callee = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else None
            pos = _REASON_CALLS.get(callee)
            if pos is None or len(node.args) <= pos:
                continue
            arg = node.args[pos]
            if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
                literal.append(f"{path.relative_to(PACKAGE)}:{node.lineno} {callee}({arg.value!r})")
            for sub in ast.walk(arg):  # a conditional of two literals is still a literal
                if isinstance(sub, ast.IfExp) and any(isinstance(b, ast.Constant) for b in (sub.body, sub.orelse)):
                    literal.append(f"{path.relative_to(PACKAGE)}:{node.lineno} {callee}(...)")
    assert not literal, literal
