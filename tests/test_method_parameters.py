"""The method pages' parameter tables (``scripts/method_parameters.py``) are current and complete: each equals a
fresh rendering of its YAML, and every key of the method's typed config is in one."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def generator(load_script):
    return load_script("method_parameters")


def test_every_table_equals_a_fresh_rendering(generator):
    assert generator.main(["--check"]) == 0, "run scripts/method_parameters.py"


@pytest.mark.parametrize("method, config", [("monosdf", "configs/methods/monosdf.yaml"),
                                            ("gs3d", "configs/methods/gs3d.yaml")])
def test_every_key_of_the_typed_config_is_documented(generator, method, config):
    from methods.registry import config_type

    [table] = [t for t in generator.TABLES if t.config == config]
    documented = {k for k, _, _ in generator.parameters((REPO / config).read_text(encoding="utf-8"), table.section)}
    keys = {f.name for f in dataclasses.fields(config_type(method))}
    assert keys == documented, f"undocumented: {sorted(keys - documented)}; not in the config: {sorted(documented - keys)}"


def test_the_parser_joins_continued_comments_and_keeps_to_its_section(generator):
    text = ("description: x   # not a parameter\n"
            "defaults:\n"
            "  a: 1            # first\n"
            "                  # ... continued\n"
            "  b: [1, 2]\n"
            "  c: {x: 1}       # pipe | inside\n"
            "scales:\n"
            "  small: {a: 2}   # not a parameter either\n")
    assert generator.parameters(text, "defaults") == [("a", "1", "first ... continued"), ("b", "[1, 2]", ""),
                                                      ("c", "{x: 1}", "pipe | inside")]
    assert [k for k, _, _ in generator.parameters("a: 1\n# header\nb: 2  # two\n", None)] == ["a", "b"]
