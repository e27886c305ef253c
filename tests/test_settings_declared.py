"""Settings are declared once: each field's type and range on the field (``Annotated[float, In(lo, hi)]``), checked
by one function; config/example.toml agrees with the declarations.

For every parameter dataclass of every service: the default lies in its declared range, a value past either end
is refused with a ConfigError naming the key, the value and the range, and the example file's values are the
defaults (so the two never disagree).
"""

from __future__ import annotations

import dataclasses
import tomllib

import pytest

from controller.control.model_correction import CorrectionParams
from controller.params import ControllerParams, ExecutorParams, ForceParams, LimitParams, TeachParams
from interfaces.errors import ConfigError
from perception.params import BoardParams as PBoard
from perception.params import CameraModelParams, InkParams, KappaParams, PerceptionParams, StainParams
from robot.lbr.params import LbrParams
from runtime.config import declared_bounds
from sim.lbr_stack.params import LbrPeerParams
from sim.params import BoardParams as SBoard
from sim.params import CameraParams, ContactParams, DirtParams, HandParams, SimParams

from .conftest import REPO

CLASSES = [ForceParams, LimitParams, ExecutorParams, TeachParams, CorrectionParams, ControllerParams, PBoard,
           InkParams, StainParams, KappaParams, CameraModelParams, PerceptionParams, SBoard, ContactParams, DirtParams,
           CameraParams, HandParams, SimParams, LbrParams, LbrPeerParams]
CASES = [(cls, name, kind, lo, hi) for cls in CLASSES for name, kind, lo, hi in declared_bounds(cls)]


def test_most_settings_are_declared():
    assert len(CASES) >= 130, len(CASES)


@pytest.mark.parametrize("cls, name, kind, lo, hi", CASES, ids=[f"{c.__name__}.{n}" for c, n, *_ in CASES])
def test_a_declared_range_holds_its_default_and_refuses_values_past_either_end(cls, name, kind, lo, hi):
    default = {f.name: f for f in dataclasses.fields(cls)}[name].default
    assert lo <= default <= hi, f"{cls.__name__}.{name} default {default} outside [{lo}, {hi}]"
    for bad in ((hi + 1 if kind is int else hi + max(abs(hi), 1.0) * 0.5), (lo - 1 if kind is int else
                                                                              lo - max(abs(lo), 1.0) * 0.5)):
        with pytest.raises(ConfigError, match=rf"\] {name} must be .*\[{lo}, {hi}\], got {bad!r}"):
            try:
                cls(**{name: bad})
            except ConfigError as exc:
                if f" {name} " not in str(exc):  # another field's cross rule fired first: not this case
                    pytest.skip(f"a cross-field rule is checked first: {exc}")
                raise


@pytest.mark.parametrize("section, root", [("controller", ControllerParams), ("perception", PerceptionParams),
                                           ("sim", SimParams), ("lbr", LbrParams), ("lbr_peer", LbrPeerParams)])
def test_the_example_config_holds_the_declared_defaults(section, root):
    example = tomllib.loads((REPO / "config" / "example.toml").read_text())
    assert root.from_table(example[section]) == root.from_table({}), section
