"""The dependencies kept below a release for a measured cost are installed as pyproject.toml pins them."""

from __future__ import annotations

import tomllib
from importlib.metadata import version
from pathlib import Path

import pytest
from packaging.requirements import Requirement

DEPENDENCIES = {
    requirement.name: requirement.specifier
    for requirement in map(
        Requirement, tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())["project"]["dependencies"]
    )
}


@pytest.mark.parametrize(
    ("name", "first_excluded"),
    [
        ("matplotlib", "3.11"),  # its libraqm text layout: the report's figures 1.15-1.25x the CPU time
        ("typer", "0.29"),  # a pydantic validator for every option at every parse
    ],
)
def test_a_pinned_dependency_is_installed_below_the_release_it_excludes(name, first_excluded):
    specifier = DEPENDENCIES[name]
    for later in (first_excluded, f"{first_excluded}.1", "99"):  # the pin is declared: that release and on
        assert later not in specifier, later
    assert version(name) in specifier  # and is what runs
