"""User effects: loaded only from a named file or a named entry point; checked; one-line errors."""

from __future__ import annotations


import pytest

from vdps_hil.model.effects import DynamicsEffect, ParamSpec
from vdps_hil.workbench.user_effects import (UserEffectError, check_effect_class, load_effect_file,
                                             load_entry_point_effects)

SIDE_FORCE = '''
from vdps_hil.model.effects import DynamicsEffect, ParamSpec

class SideForce(DynamicsEffect):
    """side_force -- F_y = side_force_n at the CG."""
    name = "side_force"
    HOOKS = ("body_wrench",)
    PARAMS = (ParamSpec("side_force_n", "N", 200.0, "constant lateral force", -5000.0, 5000.0),)

    def body_wrench(self, vel_b, omega_b, air_b):
        return (0.0, self.side_force_n, 0.0, 0.0, 0.0, 0.0)

    def regressors(self, q):
        return {"lat": {"side_force_n": 1.0}}

class _Helper:
    pass
'''


def test_effect_file_defines_candidates(tmp_path):
    p = tmp_path / "my_effect.py"
    p.write_text(SIDE_FORCE)
    classes = load_effect_file(p)
    assert [c.name for c in classes] == ["side_force"]
    assert classes[0]().body_wrench(None, None, None)[1] == 200.0


@pytest.mark.parametrize("text, msg", [
    ("raise RuntimeError('boom')\n", "RuntimeError: boom"),
    ("x = 1\n", "defines no effect"),
    ("from vdps_hil.model.effects import DynamicsEffect\nclass A(DynamicsEffect):\n    name = 'aero_drag'\n",
     "built-in"),
    ("from vdps_hil.model.effects import DynamicsEffect\nclass A(DynamicsEffect):\n    name = 'bad name'\n",
     "needs a name"),
    ("EFFECTS = [int]\n", "not a DynamicsEffect"),
])
def test_bad_effect_files(tmp_path, text, msg):
    p = tmp_path / "e.py"
    p.write_text(text)
    with pytest.raises(UserEffectError, match=msg) as ei:
        load_effect_file(p)
    assert "\n" not in str(ei.value)


def test_only_py_files_that_exist(tmp_path):
    with pytest.raises(UserEffectError, match="no such file"):
        load_effect_file(tmp_path / "nope.py")
    q = tmp_path / "e.toml"
    q.write_text("x = 1")
    with pytest.raises(UserEffectError, match=".py"):
        load_effect_file(q)


class _EP:
    def __init__(self, name, target):
        self.name, self._t, self.loaded = name, target, False

    def load(self):
        self.loaded = True
        return self._t


class Drift(DynamicsEffect):
    name = "drift"
    HOOKS = ("body_wrench",)
    PARAMS = (ParamSpec("force_n", "N", 10.0, "x force", 0.0, 100.0),)


def test_only_named_entry_points_are_loaded():
    a, b = _EP("drift", Drift), _EP("other", Drift)
    out = load_entry_point_effects(["drift"], entry_points=[a, b])
    assert out == [Drift] and a.loaded and not b.loaded
    with pytest.raises(UserEffectError, match="no entry point 'missing'"):
        load_entry_point_effects(["missing"], entry_points=[a])


def test_entry_point_group_from_the_installed_metadata():
    # nothing is installed in this group here: a name that does not exist is a one-line error
    with pytest.raises(UserEffectError, match="vdps_hil.effects"):
        load_entry_point_effects(["surely_not_installed"])


def test_class_checks():
    with pytest.raises(UserEffectError):
        check_effect_class(int, "x")

    class NoDefaults(DynamicsEffect):
        name = "needs_args"

        def __init__(self, k):
            super().__init__()

    with pytest.raises(UserEffectError, match="defaults"):
        check_effect_class(NoDefaults, "x")
    assert check_effect_class(Drift, "x") is Drift
