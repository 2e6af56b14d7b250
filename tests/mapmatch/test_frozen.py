"""The quick ``__init__`` of frozen dataclasses (:mod:`mapmatch.frozen`)."""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import pickle
from typing import Any

import pytest

from mapmatch.frozen import quick_init

#: The modules whose value objects a match makes for every trace.
MODULES = (
    "mapmatch._timing",
    "mapmatch.distance",
    "mapmatch.hmm.assemble",
    "mapmatch.hmm.candidates",
    "mapmatch.hmm.fixes",
    "mapmatch.hmm.observations",
    "mapmatch.hmm.solution",
    "mapmatch.result",
)


def _quick_classes() -> list[type]:
    found = []
    for name in MODULES:
        for value in vars(importlib.import_module(name)).values():
            if (
                isinstance(value, type)
                and value.__module__ == name
                and hasattr(vars(value).get("__init__"), "__wrapped__")
            ):
                found.append(value)
    return found


QUICK = _quick_classes()


def test_the_value_objects_of_a_match_are_made_quickly() -> None:
    names = {c.__name__ for c in QUICK}
    assert {"Candidates", "Fixes", "Observations", "Travel", "Solution", "Assembled"} <= names
    assert {"MatchedPoints", "MatchStats", "MatchResult", "DistanceCheck", "SegmentPaths"} <= names


@pytest.mark.parametrize("cls", QUICK, ids=lambda c: c.__name__)
def test_a_quick_init_makes_what_the_dataclass_s_own_made(cls: type) -> None:
    quick = vars(cls)["__init__"]
    made = quick.__wrapped__
    assert inspect.signature(quick, follow_wrapped=False) == inspect.signature(made)
    fields = dataclasses.fields(cls)
    values = {f.name: object() for f in fields}

    def by_dataclass(**given: Any) -> Any:
        obj: Any = object.__new__(cls)
        made(obj, **given)
        return obj

    for given in (
        values,
        {f.name: values[f.name] for f in fields if f.default is dataclasses.MISSING},
    ):
        quick, reference = cls(**given), by_dataclass(**given)
        for f in fields:
            assert getattr(quick, f.name) is getattr(reference, f.name), f.name
        positional = cls(*given.values())
        assert all(getattr(positional, f.name) is getattr(quick, f.name) for f in fields)
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(quick, fields[0].name, None)
    with pytest.raises(TypeError):
        cls()


@quick_init
@dataclasses.dataclass(frozen=True, slots=True)
class Slotted:
    a: int
    b: str = "b"


@quick_init
@dataclasses.dataclass(frozen=True)
class Plain:
    a: int
    b: tuple[int, ...] = ()


def test_a_quick_init_s_object_pickles_and_compares_as_before() -> None:
    for obj in (Slotted(1), Slotted(2, "x"), Plain(1), Plain(a=3, b=(1, 2))):
        assert pickle.loads(pickle.dumps(obj)) == obj
        assert dataclasses.replace(obj, a=7).a == 7
        assert hash(obj) == hash(dataclasses.replace(obj))
    assert repr(Slotted(1)) == "Slotted(a=1, b='b')"
    assert Slotted(1) != Slotted(2)
    with pytest.raises(TypeError, match="unexpected keyword"):
        Plain(a=1, c=2)  # type: ignore[call-arg]


def _class_with(b_field: Any) -> Any:
    @dataclasses.dataclass(frozen=True, slots=True)
    class Odd:
        a: int
        b: list[int] = b_field

    return Odd


@pytest.mark.parametrize(
    "make",
    [
        lambda: dataclasses.dataclass(slots=True)(
            type("Mutable", (), {"__annotations__": {"a": "int"}})
        ),
        lambda: _class_with(dataclasses.field(default_factory=list)),
        lambda: _class_with(dataclasses.field(default=1, init=False)),
        lambda: _class_with(dataclasses.field(default=1, kw_only=True)),
        lambda: dataclasses.dataclass(frozen=True)(
            type("Later", (), {"__annotations__": {"a": "int"}, "__post_init__": lambda self: None})
        ),
        lambda: dataclasses.dataclass(frozen=True)(
            type("Init", (), {"__annotations__": {"a": "int", "b": dataclasses.InitVar[int]}})
        ),
        lambda: type("NotADataclass", (), {}),
    ],
    ids=[
        "not frozen",
        "factory",
        "not in init",
        "keyword-only",
        "post_init",
        "initvar",
        "no dataclass",
    ],
)
def test_what_a_quick_init_cannot_do_is_refused(make: Any) -> None:
    with pytest.raises(TypeError, match="quick_init"):
        quick_init(make())
