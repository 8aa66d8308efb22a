"""The planner registry: versioned ids, lookups, configuration checks and registration rules."""

from __future__ import annotations

import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import pytest

import planners.registry as registry
from planners.api import Observation, Plan, Planner
from planners.classic import Classic, ClassicConfig
from planners.registry import (
    PlannerConfigError,
    PlannerSpec,
    UnknownPlannerError,
    make,
    planner_ids,
    planner_names,
    register,
    spec,
    specs,
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
    """With no version marked original, a bare name is the newest version."""
    register(throwaway, 3, _Throwaway, description="v3")
    register(throwaway, 2, _Throwaway, description="v2")
    assert spec(throwaway).version == 3
    assert spec(throwaway).id == f"{throwaway}-v3"
    assert spec(f"{throwaway}-v2").description == "v2"


def test_spec_of_classic() -> None:
    latest = spec("classic")
    assert latest.name == "classic"
    assert latest.version == max(  # every classic version is the original method
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
    planner = make("classic-v1", {"min_cluster_size": 3})
    assert isinstance(planner, Classic)
    assert isinstance(planner.config, ClassicConfig)
    assert planner.config.min_cluster_size == 3
    # Everything not given keeps its default.
    assert planner.config.view_directions == ClassicConfig().view_directions


def test_make_without_config_uses_defaults() -> None:
    planner = make("classic-v1")
    assert planner.config == ClassicConfig()
    assert make("classic-v1", None).config == ClassicConfig()


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
        make("classic-v1", config)
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


# -- ids -----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "expected"),
    [("classic-v1", ("classic", 1)), (" AEP-V2 ", ("aep", 2)), ("esm-ipp", ("esm-ipp", None)),
     ("esm-recon-v1", ("esm-recon", 1)), ("a_b-v10", ("a_b", 10))],
)
def test_parse_id(text: str, expected: tuple[str, int | None]) -> None:
    assert registry.parse_id(text) == expected
    name, version = expected
    if version is not None:
        assert registry.format_id(name, version) == text.strip().lower()


@pytest.mark.parametrize("text", ["", "9lives", "classic v1", "-v1"])
def test_parse_id_rejects_malformed_ids(text: str) -> None:
    with pytest.raises(ValueError, match="malformed planner id"):
        registry.parse_id(text)


def test_register_suggests_the_lower_case_name() -> None:
    with pytest.raises(ValueError, match="did you mean 'zzregistrytestupper'"):
        register("ZzRegistryTestUpper", 1, _Throwaway, description="bad name")


def test_register_rejects_a_class_that_is_no_planner(throwaway: str) -> None:
    with pytest.raises(TypeError, match="not a Planner subclass"):
        register(throwaway, 2, dict, description="no planner")  # type: ignore[arg-type]
    assert f"{throwaway}-v2" not in planner_ids()


# -- suggestions ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "suggested"),
    [("clasic", "classic"), ("CLASIC-V1", "classic-v1"), ("nbvp2", "nbvp"),
     ("esm-recn", "esm-recon"), ("splat-planner", "splatplanner")],
)
def test_unknown_name_suggests_the_closest_known(text: str, suggested: str) -> None:
    with pytest.raises(UnknownPlannerError) as info:
        spec(text)
    assert suggested in info.value.suggestions
    assert f"did you mean '{suggested}'" in str(info.value).lower()
    assert info.value.known == planner_ids()


def test_unknown_version_suggests_the_known_versions() -> None:
    with pytest.raises(UnknownPlannerError) as info:
        spec("aep-v9")
    assert set(info.value.suggestions) <= {"aep-v1", "aep-v2", "aep-v3", "aep-v4"}
    assert info.value.suggestions
    assert "aep-v1, aep-v2, aep-v3, aep-v4" in str(info.value)


def test_far_from_everything_suggests_nothing() -> None:
    with pytest.raises(UnknownPlannerError) as info:
        spec("qqqqqqqqqqqq")
    assert info.value.suggestions == []
    assert "did you mean" not in str(info.value).lower()


# -- load order ----------------------------------------------------------------------------------


@pytest.fixture
def fresh_registry(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The registry as a new process sees it: nothing registered or loaded yet. The real state
    comes back afterwards."""
    monkeypatch.setattr(registry, "_REGISTRY", {})
    monkeypatch.setattr(registry, "_builtins_loaded", False)
    monkeypatch.setattr(registry, "_plugins_loaded", False)
    monkeypatch.setattr(registry, "_plugin_error", None)
    yield


@pytest.mark.usefixtures("fresh_registry")
def test_register_before_the_first_lookup_keeps_the_builtins() -> None:
    register(THROWAWAY, 1, _Throwaway, description="registered first")
    assert spec("classic-v1").cls is Classic
    assert spec(THROWAWAY).description == "registered first"
    assert {"classic-v1", "aep-v1", "aep-v2", f"{THROWAWAY}-v1"} <= set(planner_ids())
    assert spec("classic").origin == registry.BUILTIN and spec("classic").builtin
    assert spec(THROWAWAY).origin == registry.DIRECT and not spec(THROWAWAY).builtin


@pytest.mark.usefixtures("fresh_registry")
def test_register_of_a_builtin_id_before_the_first_lookup_fails_at_once() -> None:
    with pytest.raises(ValueError, match="classic-v1 is already registered"):
        register("classic", 1, _Throwaway, description="shadowing the built-in")
    assert spec("classic-v1").cls is Classic


@pytest.mark.usefixtures("fresh_registry")
def test_builtins_register_all_or_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    import planners.builtin as builtin

    broken = (*builtin.BUILTINS, ("classic", 1, _Throwaway, "", "duplicate", ""))
    monkeypatch.setattr(builtin, "BUILTINS", broken)
    with pytest.raises(ValueError, match="already registered"):
        planner_ids()
    assert registry._REGISTRY == {}
    monkeypatch.setattr(builtin, "BUILTINS", broken[:-1])
    assert "classic-v1" in planner_ids()


def test_every_builtin_says_what_it_is_to_its_paper() -> None:
    """Each built-in version is marked original or variant, every name has an original
    version, and a bare name stands for its newest original version."""
    by_name: dict[str, list[PlannerSpec]] = {}
    for s in specs():
        if s.builtin:
            assert s.method in ("original", "variant"), s.id
            by_name.setdefault(s.name, []).append(s)
    for name, versions in by_name.items():
        originals = [s.version for s in versions if s.method == "original"]
        assert originals, f"{name} has no original version"
        assert spec(name).version == max(originals)
    # Where the newest version is a variant, the bare name keeps to the original.
    assert spec("fuel-v2").method == "variant" and spec("fuel").id == "fuel-v1"


@pytest.mark.usefixtures("fresh_registry")
def test_a_bare_name_without_an_original_is_its_newest_version() -> None:
    register("mine", 1, _Throwaway, description="first", method="original")
    register("mine", 2, _Throwaway, description="second", method="variant")
    register("theirs", 1, _Throwaway, description="unstated")
    register("theirs", 2, _Throwaway, description="unstated too")
    assert spec("mine").id == "mine-v1"
    assert spec("theirs").id == "theirs-v2"
    # Registered newer first, the variant still gives way to the original.
    register("late", 2, _Throwaway, description="variant first", method="variant")
    register("late", 1, _Throwaway, description="original after", method="original")
    assert spec("late").id == "late-v1"
    assert spec("theirs-v1").method == ""
    with pytest.raises(ValueError, match="method 'faithful' is none of"):
        register("mine", 3, _Throwaway, description="third", method="faithful")


# -- entry points ----------------------------------------------------------------------------------


def _distribution(root: Path, module: str, source: str, entry_points: str) -> None:
    """An installed distribution in `root`: its module and a dist-info folder."""
    (root / f"{module}.py").write_text(textwrap.dedent(source), encoding="utf-8")
    info = root / f"{module}-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(
        f"Metadata-Version: 2.1\nName: {module.replace('_', '-')}\nVersion: 1.0\n",
        encoding="utf-8")
    (info / "entry_points.txt").write_text(
        f"[{registry.ENTRY_POINT_GROUP}]\n{textwrap.dedent(entry_points)}", encoding="utf-8")


_PLUGIN = '''
from planners.api import Plan, Planner
from planners.registry import register, spec

CALLS = []


class Wanderer(Planner):
    def plan(self, obs):
        return Plan.finished("plugin")


def register_planners():
    CALLS.append(1)
    assert spec("classic-v1").builtin  # the built-ins come first
    register("zz-wanderer", 1, Wanderer, description="from a plugin")
    register("zz-wanderer", 2, Wanderer, description="from a plugin, v2")
'''


@pytest.fixture
def plugin_root(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                fresh_registry: None) -> Iterator[Path]:
    """A folder on sys.path for distributions; their modules are forgotten afterwards."""
    monkeypatch.syspath_prepend(str(tmp_path))
    before = set(sys.modules)
    yield tmp_path
    for name in set(sys.modules) - before:
        if name.startswith("zz_"):
            del sys.modules[name]


def test_entry_point_callable_registers_planners_once(plugin_root: Path) -> None:
    _distribution(plugin_root, "zz_flybo_plugin", _PLUGIN,
                  "wanderer = zz_flybo_plugin:register_planners\n")
    found = spec("ZZ-Wanderer")
    assert found.id == "zz-wanderer-v2"
    assert found.origin == "entry point wanderer = zz_flybo_plugin:register_planners"
    assert not found.builtin
    assert spec("zz-wanderer-v1").description == "from a plugin"
    assert {"zz-wanderer-v1", "zz-wanderer-v2", "classic-v1"} <= set(planner_ids())
    assert make("zz-wanderer").plan is not None
    assert sys.modules["zz_flybo_plugin"].CALLS == [1]  # loaded once, not at each lookup


def test_entry_point_module_registers_on_import(plugin_root: Path) -> None:
    source = _PLUGIN + "\nregister_planners()\n"
    _distribution(plugin_root, "zz_flybo_module_plugin", source,
                  "wanderer = zz_flybo_module_plugin\n")
    assert spec("zz-wanderer").id == "zz-wanderer-v2"


def test_entry_points_are_loaded_lazily(plugin_root: Path) -> None:
    register(THROWAWAY, 1, _Throwaway, description="registering loads no plugin")
    _distribution(plugin_root, "zz_flybo_plugin", _PLUGIN,
                  "wanderer = zz_flybo_plugin:register_planners\n")
    assert "zz_flybo_plugin" not in sys.modules
    assert "zz-wanderer" in planner_names()


@pytest.mark.parametrize(
    ("source", "target", "why"),
    [
        ("raise RuntimeError('boom')", "zz_flybo_broken:nothing", "RuntimeError: boom"),
        ("x = 1", "zz_flybo_broken:missing", "AttributeError"),
        ("x = 1", "zz_flybo_broken:x", "neither a module nor a callable"),
        (_PLUGIN + "\ndef twice():\n    register_planners()\n    register_planners()\n",
         "zz_flybo_broken:twice", "already registered"),
    ],
)
def test_failing_entry_point_is_named_in_the_error(
    plugin_root: Path, source: str, target: str, why: str,
) -> None:
    _distribution(plugin_root, "zz_flybo_broken", source, f"broken = {target}\n")
    with pytest.raises(registry.PlannerPluginError) as info:
        spec("classic")
    message = str(info.value)
    assert f"broken = {target}" in message
    assert "zz-flybo-broken 1.0" in message
    assert registry.ENTRY_POINT_GROUP in message
    assert why in message
    # Every later lookup fails the same way, and the plugin left no planner half registered.
    with pytest.raises(registry.PlannerPluginError, match=f"broken = {target}"):
        planner_ids()
    assert "zz-wanderer" not in registry._REGISTRY or not registry._REGISTRY["zz-wanderer"]
    assert "classic" in registry._REGISTRY
