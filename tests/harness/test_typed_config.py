"""The one typed-config mechanism (bench/data/config.py) and its use by the methods and protocols."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Annotated, Any, Literal

import pytest
import yaml

from bench.data.config import Range, config_record, load_config
from bench.data.errors import BenchInputError


@dataclass(frozen=True)
class _Inner:
    k: int


@dataclass(frozen=True)
class _Example:
    lr: Annotated[float, Range(lo=0, lo_open=True)]
    steps: int
    mode: Literal["a", "b"]
    flag: bool
    clamp: tuple[float, float]
    fractions: tuple[float, ...]
    maybe: Annotated[float, Range(lo=0)] | None
    inside_out: bool | Literal["auto"]
    extra: dict[str, Any]
    inner: _Inner
    note: str = "default"

    def check(self) -> str | None:
        return "clamp must be increasing" if self.clamp[0] > self.clamp[1] else None


GOOD = {"lr": 2e-3, "steps": 10, "mode": "a", "flag": True, "clamp": [0.1, 0.2], "fractions": [0.5, 1],
        "maybe": None, "inside_out": "auto", "extra": {}, "inner": {"k": 3}}


def test_a_good_mapping_fills_the_dataclass_with_normalised_values():
    cfg = load_config(_Example, GOOD, "x.yaml")
    assert cfg.clamp == (0.1, 0.2) and cfg.fractions == (0.5, 1.0) and isinstance(cfg.fractions[1], float)
    assert cfg.inner == _Inner(3) and cfg.note == "default" and cfg.inside_out == "auto"
    assert load_config(_Example, {**GOOD, "inside_out": False}, "x.yaml").inside_out is False
    rec = config_record(cfg)
    assert rec["clamp"] == [0.1, 0.2] and rec["inner"] == {"k": 3}
    assert load_config(_Example, rec, "x.yaml") == cfg  # round trip


@pytest.mark.parametrize("change, message", [
    ({"lr_typo": 1.0}, "unknown config key 'lr_typo'"),
    ({"lr": "1e-4"}, "'lr' must be a number"),  # YAML 1.1 reads 1e-4 (no dot) as a string
    ({"lr": 0.0}, r"'lr' must be a number in \(0, inf\)"),
    ({"steps": 2.5}, "'steps' must be an integer"),
    ({"steps": True}, "'steps' must be an integer"),
    ({"mode": "c"}, "'mode' must be one of 'a', 'b'"),
    ({"flag": "yes"}, "'flag' must be true or false"),
    ({"clamp": [0.1]}, "'clamp' must be a list"),
    ({"clamp": [0.3, 0.2]}, "clamp must be increasing"),
    ({"maybe": -1.0}, "'maybe' must be"),
    ({"inside_out": "maybe"}, "'inside_out' must be true or false or one of 'auto'"),
    ({"inner": {"k": 1, "j": 2}}, "unknown config key 'inner.j'"),
    ({"fractions": [0.5, "x"]}, r"'fractions\[1\]' must be a number"),
])
def test_bad_values_are_one_error_naming_the_file_and_key(change, message):
    with pytest.raises(BenchInputError, match=message) as err:
        load_config(_Example, {**GOOD, **change}, "configs/x.yaml")
    assert str(err.value).startswith("configs/x.yaml: ")


def test_a_missing_key_without_default_is_an_error():
    data = dict(GOOD)
    del data["steps"]
    with pytest.raises(BenchInputError, match="config key 'steps' has no value"):
        load_config(_Example, data, "x.yaml")


def test_yaml_scientific_notation_pitfall_is_caught_in_a_method_preset():
    with pytest.raises(BenchInputError, match="'lr' must be a number"):
        from methods.registry import method_config

        method_config("monosdf", "tiny", {"lr": yaml.safe_load("1e-4")})


METHODS = ("monosdf", "monoinstance", "gs3d", "fsgs", "monoinstance_gs", "oracle_tsdf")


@pytest.mark.parametrize("name", METHODS)
def test_every_preset_is_typed_and_its_values_live_only_in_the_yaml(name):
    """Each shipped method declares a typed config whose keys are exactly its YAML's, with no dataclass
    defaults (a second copy of a value would drift), and every scale preset validates."""
    from methods.registry import config_type, method_config, typed_method_config

    ctype = config_type(name)
    assert ctype is not None
    assert all(f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING for f in dataclasses.fields(ctype))
    for scale in ("tiny", "small", "medium", "large"):
        resolved = method_config(name, scale)
        assert set(resolved) == {f.name for f in dataclasses.fields(ctype)}, scale
        typed = typed_method_config(name, scale)
        assert config_record(typed) == resolved  # the same values (ints read as floats compare equal)


def test_protocol_parameters_are_typed_registry_entries():
    from bench.evaluate import PROTOCOL_REGISTRY, protocol_params

    assert set(PROTOCOL_REGISTRY) == {"scannet", "replica", "dtu", "llff"}
    for name, entry in PROTOCOL_REGISTRY.items():
        for scale in ("tiny", "small", "medium", "large"):
            assert isinstance(protocol_params(name, scale), entry.params_type)
    assert protocol_params("scannet", "small").tsdf_voxel == 0.02 and protocol_params("scannet", "large").tsdf_voxel == 0.01


def test_bench_config_prints_the_checked_config_and_rejects_bad_overrides(capsys):
    from bench.cli import main

    assert main(["config", "monosdf", "--scale", "tiny", "--set", "lr=1e-3", "prune_weight=0"]) == 0
    out = capsys.readouterr().out
    assert "typed: methods.monosdf.config.MonoSDFConfig" in out
    assert any(line.startswith("lr ") and "0.001" in line and "# a number in (0, inf)" in line for line in out.splitlines())
    assert main(["config", "monosdf", "--set", "lr=fast"]) == 2
    assert "config key 'lr' must be a number in (0, inf) (got 'fast')" in capsys.readouterr().err
    assert main(["config", "monosdf", "--set", "lr_typo=1"]) == 2  # not a key of the method
    assert main(["config", "monosdf", "--set", "depth_wieght=0.1"]) == 2  # a typo: the nearest key is named first
    err = capsys.readouterr().err
    assert "override 'depth_wieght' is not a config key of 'monosdf'; did you mean 'depth_weight'? (keys: [" in err
    assert main(["config", "monosdff"]) == 2  # not a method: the known ones are listed
    err = capsys.readouterr().err
    assert "no config file for method 'monosdff': not a known method (known: " in err and "monoinstance" in err


def test_id_neutral_keys_leave_job_ids_alone_only_at_their_neutral_value():
    """Keys added after results were published (``id_neutral`` in a method's YAML) are left out of the
    job identity at their neutral value (so published rows keep matching) and are part of it otherwise;
    inherited by ``base:`` variants (monoinstance from monosdf)."""
    from methods.registry import identity_config, method_config

    for name in ("monosdf", "monoinstance"):
        default = method_config(name, "tiny")
        ident = identity_config(name, default)
        assert "use_grid" in default and "use_grid" not in ident and "mlp_skip" not in ident
        assert "iterations" in ident
        mlp = identity_config(name, method_config(name, "tiny", {"use_grid": False, "mlp_skip": [2], "mlp_hidden": 64}))
        assert mlp["use_grid"] is False and mlp["mlp_skip"] == [2] and "weight_norm" not in mlp


def test_flush_denormals_stays_out_of_the_base_id_and_enters_the_full_id():
    """``flush_denormals`` (float-rounding kind): at its default the base id that tables match rows by is
    the one of the rows published before the key existed (IEEE arithmetic); the full id that decides reuse differs, so
    an IEEE row is not reused as a flushed one."""
    from bench.jobs import JobPlan
    from bench.runner import job_id_for
    from methods.registry import method_config

    plan = JobPlan("t", "Base", "monosdf", {}, "scannet", "scannet", "scannet", "scannet_like_tiny", 0, "tiny")
    on = method_config("monosdf", "tiny")
    before = {k: v for k, v in on.items() if k != "flush_denormals"}  # a config from before the key
    assert on["flush_denormals"] is True
    assert job_id_for(plan, on) == job_id_for(plan, before)
    assert job_id_for(plan, on, threads=1) != job_id_for(plan, before, threads=1)


def test_mlp_skip_that_cannot_be_built_is_one_config_error():
    from methods.registry import method_config

    with pytest.raises(BenchInputError, match="mlp_skip"):
        method_config("monosdf", "tiny", {"use_grid": False, "mlp_layers": 4, "mlp_skip": [5], "mlp_hidden": 64})
    with pytest.raises(BenchInputError, match="mlp_skip"):
        method_config("monosdf", "tiny", {"use_grid": False, "mlp_layers": 4, "mlp_skip": [2], "mlp_hidden": 32})
