"""The planner registry: versioned ids, lookups, configuration checks and registration rules."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

import planners.registry as registry
from planners.api import Observation, Plan, Planner
from planners.classic import Classic, ClassicConfig
from planners.registry import (
    PlannerConfigError,
    UnknownPlannerError,
    make,
    planner_ids,
    planner_names,
    register,
    spec,
)

THROWAWAY = "zz_registry_test_throwaway"


class _Throwaway(Planner):
    """A planner that never flies anywhere; only registered by the fixture below."""

    def plan(self, obs: Observation) -> Plan:
        return Plan.finished("throwaway")


@pytest.fixture
def throwaway() -> Iterator[str]:
    """Registers `_Throwaway` as `THROWAWAY`-v1 and removes every version of it afterwards."""
    planner_ids()  # load the built-ins first, so the teardown cannot race their registration
    assert THROWAWAY not in registry._REGISTRY
    register(THROWAWAY, 1, _Throwaway, description="throwaway test planner")
    try:
        yield THROWAWAY
    finally:
        registry._REGISTRY.pop(THROWAWAY, None)


def test_planner_ids_contain_classic_v1() -> None:
    ids = planner_ids()
    assert "classic-v1" in ids
    assert ids == sorted(ids)
    assert "classic" in planner_names()


def test_spec_without_version_gives_the_latest(throwaway: str) -> None:
    register(throwaway, 3, _Throwaway, description="v3")
    register(throwaway, 2, _Throwaway, description="v2")
    assert spec(throwaway).version == 3
    assert spec(throwaway).id == f"{throwaway}-v3"
    assert spec(f"{throwaway}-v2").description == "v2"


def test_spec_of_classic() -> None:
    latest = spec("classic")
    assert latest.name == "classic"
    assert latest.version == max(
        int(i.rsplit("-v", 1)[1]) for i in planner_ids() if i.startswith("classic-v")
    )
    v1 = spec("classic-v1")
    assert v1.id == "classic-v1"
    assert v1.version == 1
    assert v1.cls is Classic
    assert v1.config_model is ClassicConfig
    assert v1.description


@pytest.mark.parametrize("text", ["CLASSIC-V1", "  classic-v1  ", "Classic-v1", "\tclassic-V1\n"])
def test_spec_is_case_and_space_insensitive(text: str) -> None:
    assert spec(text).id == "classic-v1"


def test_spec_of_unknown_name_lists_the_known_ids() -> None:
    with pytest.raises(UnknownPlannerError) as info:
        spec("no-such-planner")
    message = str(info.value)
    assert "no-such-planner" in message
    for planner_id in planner_ids():
        assert planner_id in message
    assert isinstance(info.value, ValueError)


@pytest.mark.parametrize("text", ["", "   ", "9lives", "classic v1", "clas$ic"])
def test_spec_of_malformed_name_raises_unknown(text: str) -> None:
    with pytest.raises(UnknownPlannerError, match="classic-v1"):
        spec(text)


def test_spec_of_unknown_version_lists_the_known_versions() -> None:
    with pytest.raises(UnknownPlannerError) as info:
        spec("classic-v9")
    message = str(info.value)
    assert "v9" in message
    assert "classic-v1" in message


def test_make_applies_config() -> None:
    planner = make("classic", {"min_cluster_size": 3})
    assert isinstance(planner, Classic)
    assert isinstance(planner.config, ClassicConfig)
    assert planner.config.min_cluster_size == 3
    # Everything not given keeps its default.
    assert planner.config.view_directions == ClassicConfig().view_directions


def test_make_without_config_uses_defaults() -> None:
    planner = make("classic-v1")
    assert planner.config == ClassicConfig()
    assert make("classic", None).config == ClassicConfig()


def test_make_gives_a_new_instance_each_time() -> None:
    assert make("classic") is not make("classic")


@pytest.mark.parametrize(
    "config",
    [
        {"no_such_key": 1},
        {"min_cluster_size": "many"},
        {"min_cluster_size": 0},
        {"view_directions": [1, 2]},
        {"max_view_elevation_deg": 95.0},
    ],
)
def test_make_rejects_invalid_config(config: dict[str, object]) -> None:
    with pytest.raises(PlannerConfigError, match="classic-v1") as info:
        make("classic", config)
    assert isinstance(info.value, ValueError)
    # The message names the offending setting.
    (key,) = config
    assert key in str(info.value)


def test_make_of_unknown_planner_raises_unknown() -> None:
    with pytest.raises(UnknownPlannerError):
        make("no-such-planner", {})


def test_registered_planner_is_listed_and_made(throwaway: str) -> None:
    assert f"{throwaway}-v1" in planner_ids()
    assert throwaway in planner_names()
    planner = make(throwaway)
    assert isinstance(planner, _Throwaway)


def test_register_duplicate_id_raises(throwaway: str) -> None:
    with pytest.raises(ValueError, match="already registered"):
        register(throwaway, 1, _Throwaway, description="again")
    with pytest.raises(ValueError, match="already registered"):
        register("classic", 1, _Throwaway, description="shadowing the built-in")
    # The failed registrations changed nothing.
    assert spec("classic-v1").cls is Classic
    assert spec(f"{throwaway}-v1").description == "throwaway test planner"


@pytest.mark.parametrize(
    "name",
    [
        "ZzRegistryTestUpper",
        f"{THROWAWAY.upper()}",
        f"{THROWAWAY}-v2",
        "",
        "1starts_with_digit",
        "has space",
    ],
)
def test_register_invalid_name_raises(name: str) -> None:
    before = {k: dict(v) for k, v in registry._REGISTRY.items()}
    try:
        with pytest.raises(ValueError, match="invalid planner name"):
            register(name, 1, _Throwaway, description="bad name")
        assert before == registry._REGISTRY
    finally:
        # Never leave a stray entry behind, even if the registry wrongly accepted the name.
        for key in set(registry._REGISTRY) - set(before):
            registry._REGISTRY.pop(key, None)
