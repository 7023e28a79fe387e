"""base.cores and the core counts that may be written `auto` (base.torch_threads, the
simulation stages' workers): auto is the machine's count, one-line errors name the key."""

from __future__ import annotations

import os

import pytest

from clutterbench.config import (
    BaseConfig,
    load_base,
    load_params,
    load_section,
    machine_cores,
    resolve_cores,
)
from clutterbench.data.config import GenerateConfig
from clutterbench.data.slides import SlideDataConfig
from clutterbench.errors import ClutterbenchError
from clutterbench.support.config import SupportEvalConfig
from clutterbench.trials.ch3.config import GamesConfig
from clutterbench.trials.config import TrialsConfig


@pytest.fixture
def cores(monkeypatch):
    """Make this machine have `n` CPUs for this process."""

    def set_cores(n: int) -> None:
        monkeypatch.setattr(os, "sched_getaffinity", lambda pid: set(range(n)), raising=False)
        monkeypatch.setattr(os, "cpu_count", lambda: n + 100)  # the affinity count wins

    return set_cores


def test_auto_is_the_affinity_count(cores):
    cores(5)
    assert machine_cores() == 5
    base = load_base({"base": {"cores": "auto", "torch_threads": "auto"}})
    assert (base.cores, base.torch_threads) == (5, 5)
    assert BaseConfig().cores == 5  # the default, built directly


def test_auto_is_cpu_count_without_affinity(monkeypatch):
    monkeypatch.delattr(os, "sched_getaffinity", raising=False)
    monkeypatch.setattr(os, "cpu_count", lambda: 3)
    assert machine_cores() == 3


def test_stage_workers_auto_are_base_cores(cores):
    cores(6)
    params = {"base": {"scale": "tiny"}, "generate": {"workers": "auto"}}
    assert load_section(GenerateConfig, "generate", params).workers == 6
    params["base"]["cores"] = 3  # an explicit base.cores is what auto means
    assert load_section(GenerateConfig, "generate", params).workers == 3
    assert load_base(params).torch_threads == 2  # not auto: its own value
    params["generate"]["workers"] = {"tiny": "auto", "default": 4, "paper": 16}
    assert load_section(GenerateConfig, "generate", params).workers == 3
    params["generate"]["workers"] = 7
    assert load_section(GenerateConfig, "generate", params).workers == 7


@pytest.mark.parametrize("scale", ["tiny", "default"])
def test_params_yaml_gives_todays_counts_on_two_cores(root, cores, scale):
    cores(2)
    params = load_params(root / "params.yaml")
    params["base"]["scale"] = scale
    base = load_base(params)
    assert (base.cores, base.torch_threads) == (2, 2)
    assert load_section(GenerateConfig, "generate", params).workers == 2
    assert load_section(SupportEvalConfig, "support", params).workers == (
        1 if scale == "tiny" else 2
    )
    data = load_section(SlideDataConfig, "yamakuzushi.data", params)
    assert data.workers == 2
    trials = load_section(TrialsConfig, "trials", params)
    assert trials.workers == (1 if scale == "tiny" else 2)
    assert load_section(GamesConfig, "yamakuzushi.games", params).workers == 2


@pytest.mark.parametrize(
    "cls, section", [(TrialsConfig, "trials"), (GamesConfig, "yamakuzushi.games")]
)
def test_trials_workers_auto_are_base_cores(cores, cls, section):
    cores(6)
    params = {"base": {"scale": "tiny"}, "trials": {"workers": "auto"}}
    params["yamakuzushi"] = {"games": {"workers": "auto"}}
    assert load_section(cls, section, params).workers == 6
    params["base"]["cores"] = 3
    assert load_section(cls, section, params).workers == 3
    params["trials"]["workers"] = params["yamakuzushi"]["games"]["workers"] = 5
    assert load_section(cls, section, params).workers == 5
    params["trials"]["workers"] = params["yamakuzushi"]["games"]["workers"] = 0
    with pytest.raises(ClutterbenchError, match=rf"^{section}\.workers: 0 is not auto or an"):
        load_section(cls, section, params)


@pytest.mark.parametrize("n", [1, 16])
def test_params_yaml_trials_at_paper_scale_take_every_core(root, cores, n):
    cores(n)
    params = load_params(root / "params.yaml")
    params["base"]["scale"] = "paper"
    assert load_section(TrialsConfig, "trials", params).workers == n
    assert load_section(GamesConfig, "yamakuzushi.games", params).workers == n


@pytest.mark.parametrize("bad", ["many", 0, -2, 1.5, True, None])
@pytest.mark.parametrize("key", ["cores", "torch_threads"])
def test_a_bad_base_count_is_one_line_naming_its_key(bad, key):
    with pytest.raises(ClutterbenchError) as err:
        load_base({"base": {key: bad}})
    message = str(err.value)
    assert message.startswith(f"base.{key}: ") and "\n" not in message
    assert "auto" in message


@pytest.mark.parametrize("bad", ["many", 0])
def test_a_bad_workers_value_is_one_line_naming_its_key(bad):
    params = {"base": {}, "generate": {"workers": bad}}
    with pytest.raises(ClutterbenchError, match=r"^generate\.workers: .* is not auto or an"):
        load_section(GenerateConfig, "generate", params)


def test_resolve_cores():
    assert resolve_cores("auto", 4) == 4
    assert resolve_cores(3, 4) == 3
    with pytest.raises(ClutterbenchError, match=r"^trials\.workers: 'many' is not auto"):
        resolve_cores("many", 4, "trials.workers")
