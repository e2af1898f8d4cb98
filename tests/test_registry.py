"""The sampler registry: entry-point discovery (faked and real), errors and warnings."""

from __future__ import annotations

import subprocess
import sys
import warnings
from types import SimpleNamespace

import pytest

from isf.exceptions import ConfigError, ISFError, PluginLoadError, SamplerNotFound
from isf.samplers import (
    RegretSampler,
    UniformSampler,
    available_samplers,
    get_sampler,
    refresh_samplers,
    register_sampler,
    registry,
)


class FakeEntryPoint:
    """Duck-typed importlib.metadata.EntryPoint: name, value, dist, load()."""

    def __init__(self, name, target, dist="fake-dist", version="1.0", value=None):
        self.name = name
        self.value = value or f"fake_module:{name.title()}"
        self.dist = None if dist is None else SimpleNamespace(name=dist, version=version)
        self._target = target
        self.loads = 0

    def load(self):
        self.loads += 1
        if isinstance(self._target, BaseException):
            raise self._target
        return self._target


def _named(name, base=UniformSampler):
    """A Sampler subclass whose ``name`` matches its entry point."""
    return type(f"{name.title()}Sampler", (base,), {"name": name})


@pytest.fixture
def fake_eps(monkeypatch):
    """Replace the entry-point seam with a list the test fills; count the reads."""
    eps: list[FakeEntryPoint] = []
    reads = []

    def seam():
        reads.append(1)
        return list(eps)

    monkeypatch.setattr(registry, "_entry_points", seam)
    monkeypatch.setattr(registry, "_registered", {})
    refresh_samplers()
    yield SimpleNamespace(eps=eps, reads=reads)
    refresh_samplers()


def test_listing_is_sorted_and_does_not_import(fake_eps):
    fake_eps.eps += [
        FakeEntryPoint("uniform", UniformSampler, dist="isf", version="0.1.0"),
        FakeEntryPoint("alpha", _named("alpha", RegretSampler), "isf-sampler-alpha", "2.3"),
    ]
    infos = available_samplers()
    assert list(infos) == ["alpha", "uniform"]
    assert infos["alpha"].distribution == "isf-sampler-alpha"
    assert infos["alpha"].version == "2.3"
    assert infos["alpha"].value == "fake_module:Alpha"
    assert infos["alpha"].description is None
    assert all(ep.loads == 0 for ep in fake_eps.eps)


def test_listing_is_cached_until_refreshed(fake_eps):
    fake_eps.eps.append(FakeEntryPoint("uniform", UniformSampler))
    available_samplers()
    get_sampler("uniform")
    assert len(fake_eps.reads) == 1
    fake_eps.eps.append(FakeEntryPoint("late", _named("late")))
    assert "late" not in available_samplers()
    refresh_samplers()
    assert "late" in available_samplers()
    assert len(fake_eps.reads) == 2


def test_load_fills_descriptions(fake_eps):
    fake_eps.eps.append(FakeEntryPoint("regret", RegretSampler))
    assert available_samplers(load=True)["regret"].description == RegretSampler.description


def test_get_sampler_builds_with_params(fake_eps):
    fake_eps.eps.append(FakeEntryPoint("regret", RegretSampler))
    sampler = get_sampler("regret", n_clusters=4, gamma=0.5)
    assert type(sampler) is RegretSampler
    assert (sampler.n_clusters, sampler.gamma) == (4, 0.5)


def test_duplicate_names_warn_naming_both_distributions(fake_eps):
    fake_eps.eps += [
        FakeEntryPoint("dup", _named("dup"), dist="first-dist", version="1.0"),
        FakeEntryPoint("dup", _named("dup", RegretSampler), dist="second-dist", version="2.0"),
    ]
    with pytest.warns(RuntimeWarning, match=r"'dup'.*first-dist 1\.0.*second-dist 2\.0"):
        infos = available_samplers()
    assert infos["dup"].distribution == "first-dist"
    assert isinstance(get_sampler("dup"), UniformSampler)


def test_broken_plugin_raises_when_asked_for_and_warns_when_listed(fake_eps):
    cause = ImportError("No module named 'missing_dependency'")
    fake_eps.eps += [
        FakeEntryPoint("broken", cause, dist="isf-sampler-broken", version="0.9"),
        FakeEntryPoint("uniform", UniformSampler),
    ]
    assert "broken" in available_samplers()  # listing without loading cannot know
    match = "'broken'.*isf-sampler-broken 0.9.*missing_dependency"
    with pytest.raises(PluginLoadError, match=match) as info:
        get_sampler("broken")
    assert info.value.__cause__ is cause
    with pytest.warns(RuntimeWarning, match="skipping sampler 'broken'.*isf-sampler-broken"):
        loaded = available_samplers(load=True)
    assert list(loaded) == ["uniform"]


@pytest.mark.parametrize(
    "target", [dict, len, 42, object()], ids=["class", "function", "int", "instance"]
)
def test_entry_point_must_name_a_sampler_subclass(fake_eps, target):
    fake_eps.eps.append(FakeEntryPoint("odd", target, dist="odd-dist"))
    match = "'odd'.*odd-dist.*not a subclass of isf.samplers.Sampler"
    with pytest.raises(PluginLoadError, match=match):
        get_sampler("odd")
    with pytest.warns(RuntimeWarning, match="skipping sampler 'odd'"):
        assert "odd" not in available_samplers(load=True)


def test_entry_point_name_must_match_class_name(fake_eps):
    fake_eps.eps.append(FakeEntryPoint("alias", UniformSampler, dist="alias-dist"))
    with pytest.warns(RuntimeWarning, match="'alias'.*alias-dist.*'uniform'.*agree"):
        assert isinstance(get_sampler("alias"), UniformSampler)


def test_unknown_name_lists_installed_names_and_how_to_install(fake_eps):
    fake_eps.eps += [
        FakeEntryPoint("uniform", UniformSampler, dist="isf"),
        FakeEntryPoint("regret", RegretSampler, dist="isf"),
    ]
    with pytest.raises(SamplerNotFound) as info:
        get_sampler("antipodal")
    message = str(info.value)
    assert "\n" not in message
    assert "'antipodal'" in message and "installed: regret, uniform" in message
    assert "pip install" in message and "isf.samplers" in message
    assert isinstance(info.value, LookupError) and isinstance(info.value, ISFError)


def test_unknown_name_without_builtins_says_isf_is_not_installed(fake_eps):
    with pytest.raises(SamplerNotFound, match=r"installed: none \(isf's own built-ins are missing"):
        get_sampler("regret")


def test_entry_point_without_distribution(fake_eps):
    fake_eps.eps.append(FakeEntryPoint("orphan", _named("orphan"), dist=None))
    info = available_samplers()["orphan"]
    assert (info.distribution, info.version) == (None, None)
    assert get_sampler("orphan").name == "orphan"


def test_register_sampler_at_run_time_wins_over_entry_points(fake_eps):
    fake_eps.eps.append(FakeEntryPoint("mine", _named("mine"), dist="some-dist"))
    register_sampler("mine", RegretSampler)
    info = available_samplers()["mine"]
    assert info.distribution is None and info.value == "isf.samplers.regret:RegretSampler"
    assert info.source == "registered at run time"
    assert type(get_sampler("mine")) is RegretSampler
    assert fake_eps.eps[0].loads == 0


@pytest.mark.parametrize("name", ["Mine", "my-sampler", "", 3])
def test_register_sampler_rejects_bad_names(fake_eps, name):
    with pytest.raises(ConfigError, match="a-z0-9_"):
        register_sampler(name, UniformSampler)


def test_register_sampler_rejects_non_samplers(fake_eps):
    with pytest.raises(PluginLoadError, match="not a subclass"):
        register_sampler("mine", dict)


def test_get_sampler_accepts_classes_and_instances(fake_eps):
    assert type(get_sampler(RegretSampler, n_clusters=2)) is RegretSampler
    instance = UniformSampler()
    assert get_sampler(instance) is instance
    with pytest.raises(ConfigError, match="instance"):
        get_sampler(instance, gamma=0.1)
    with pytest.raises(ConfigError, match="Sampler subclass"):
        get_sampler(3.5)
    assert len(fake_eps.reads) <= 1


def test_unknown_parameter_lists_accepted_ones(fake_eps):
    with pytest.raises(ConfigError, match="clusters.*accepted parameters: n_clusters, gamma"):
        get_sampler(RegretSampler, clusters=3)


def test_invalid_parameter_value_is_a_config_error(fake_eps):
    fake_eps.eps.append(FakeEntryPoint("regret", RegretSampler))
    with pytest.raises(ConfigError, match="gamma"):
        get_sampler("regret", gamma=-1.0)


# --------------------------------------------------- the real, installed entry points


def _real_infos():
    refresh_samplers()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a duplicate or broken real plugin fails the test
        return available_samplers(load=True)


def test_builtins_are_registered_through_entry_points():
    """Needs isf installed (pip install -e .): the built-ins come from its own entry points."""
    infos = _real_infos()
    assert infos["regret"].value == "isf.samplers.regret:RegretSampler"
    assert infos["uniform"].value == "isf.samplers.uniform:UniformSampler"
    assert infos["regret"].distribution == infos["uniform"].distribution == "isf"
    assert type(get_sampler("regret")) is RegretSampler
    assert type(get_sampler("uniform")) is UniformSampler


def test_real_plugin_installed():
    """Needs pip install -e plugins/isf-sampler-normal."""
    infos = _real_infos()
    assert "normal" in infos
    assert infos["normal"].distribution == "isf-sampler-normal"
    assert infos["normal"].value == "isf_sampler_normal:NormalSampler"
    assert get_sampler("normal").name == "normal"


def test_isf_never_imports_plugins():
    code = (
        "import sys, isf.samplers, isf.testing\n"
        "isf.samplers.available_samplers()\n"
        "assert 'isf_sampler_normal' not in sys.modules, 'imported without being asked'\n"
        "isf.samplers.get_sampler('normal')\n"
        "assert 'isf_sampler_normal' in sys.modules, 'get_sampler did not import it'\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
