"""The collection rule of tests/reference_runs/conftest.py: a test is skipped for a missing reference
code only when it carries that code's marker and the binary is absent, and the reason names the binary
and its install command; a parameter id that names a code is no reason to skip."""

import importlib.util
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent


def _rule():
    spec = importlib.util.spec_from_file_location("reference_runs_conftest", HERE / "conftest.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.code_skip_reason


class _Item:
    """A collected test as far as the rule looks at it: its markers."""

    def __init__(self, *markers):
        self.markers = set(markers)

    def get_closest_marker(self, name):
        return object() if name in self.markers else None


def _absent(binary):
    return None


def _present(binary):
    return f"/usr/bin/{binary}"


def test_a_marked_test_is_skipped_only_where_its_binary_is_absent():
    rule = _rule()
    reason = rule(_Item("liggghts"), which=_absent)
    assert reason == "needs the liggghts binary (marker liggghts), which is not installed (apt-get install liggghts)"
    assert rule(_Item("liggghts"), which=_present) is None


def test_a_test_without_a_code_marker_is_never_skipped_by_the_rule():
    rule = _rule()
    assert rule(_Item(), which=_absent) is None
    assert rule(_Item("slow"), which=_absent) is None


@pytest.mark.parametrize("code", ["liggghts"])
def test_a_parameter_id_naming_a_code_is_no_reason_to_skip(code, request):
    """``test_x[liggghts]`` has ``liggghts`` among its keywords (what the former rule skipped on)
    but no marker: with the binary absent it still runs."""
    assert code in request.node.keywords
    assert _rule()(request.node, which=_absent) is None
