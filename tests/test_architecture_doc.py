"""docs/architecture.md's tables against the code: the protocol table names each member of the Scenario
protocol, the capabilities table each field of Capabilities, and the scenario list each kind."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

from kalcal.capabilities import Capabilities
from kalcal.scenarios import scenario_names
from kalcal.scenarios.protocol import Scenario

DOC = (Path(__file__).resolve().parents[1] / "docs" / "architecture.md").read_text(encoding="utf-8")


def _first_column(header: str) -> set[str]:
    """The backquoted names of the first column of the table whose header row starts with ``header``."""
    start = DOC.index(f"| {header} |")
    rows = []
    for line in DOC[start:].splitlines()[2:]:
        if not line.startswith("|"):
            break
        rows.append(line.split("|")[1])
    return {re.match(r"\w+", name).group(0) for row in rows for name in re.findall(r"`([^`]+)`", row)}


def test_the_protocol_table_names_every_member_of_the_protocol():
    members = {name for name in vars(Scenario) if not name.startswith("_")} | set(Scenario.__annotations__)
    assert "NAME" in members and _first_column("member") == members


def test_the_capabilities_table_names_every_field():
    assert _first_column("capability") == {f.name for f in dataclasses.fields(Capabilities)}


def test_the_opening_names_every_kind_of_scenario():
    opening = DOC.split("\n\n", 2)[1]
    assert all(name in opening for name in scenario_names()) and "a model file" in opening and "written as code" in opening
