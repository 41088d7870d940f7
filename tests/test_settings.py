"""Each setting is declared once, in the core (pinsettle::settingFields()); the checks, the Python
properties and their docs, the Python types, the type stubs, the command-line flags and the
docs follow from that list, and these tests fail where one of them drifts from it."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pinsettle
import pytest
from pinsettle import _core
from pinsettle._settings import SETTING_FIELDS, SETTING_TYPES, settings_stub

ROOT = Path(__file__).resolve().parents[1]
FIELDS = {f["name"]: f for f in SETTING_FIELDS}


def test_the_python_types_are_the_fields():
    assert list(SETTING_TYPES) == list(FIELDS)
    assert set(pinsettle.Settings().to_dict()) == set(FIELDS)
    assert len(FIELDS) == len(SETTING_FIELDS)  # no name twice


def test_each_property_has_the_fields_help_and_default():
    defaults = pinsettle.Settings()
    for name, field in FIELDS.items():
        prop = getattr(_core.Settings, name)
        assert prop.__doc__ == field["help"], name
        assert getattr(defaults, name) == field["default"], name
        assert f"``{name}``" in pinsettle.Settings.__doc__, name  # the class says it too


def test_the_stub_is_made_from_the_fields():
    stub = (ROOT / "python" / "pinsettle" / "_core.pyi").read_text(encoding="utf-8")
    assert "class Settings:\n" + settings_stub() in stub


def test_every_setting_is_in_the_docs():
    text = (ROOT / "docs" / "settings.md").read_text(encoding="utf-8")
    for name in FIELDS:
        assert f"`{name}`" in text, name


@pytest.mark.parametrize("name", [n for n, f in FIELDS.items() if f["kind"] != "switch"])
def test_a_value_against_the_rule_is_refused_with_its_words(name):
    field = FIELDS[name]
    settings = pinsettle.Settings()
    if field["kind"] == "choice":
        with pytest.raises(ValueError, match=f"^{name} must be"):
            setattr(settings, name, "neither")
        return
    expected = re.escape(field["expected"])
    if field["kind"] == "auto_switch":  # True, False or 'auto': another word is refused as set
        with pytest.raises(ValueError, match=f"^{name} must be {expected}, got 'neither'$"):
            setattr(settings, name, "neither")
        return
    bad = -1 if field["kind"] == "integer" else -1.0
    if field["kind"] == "auto_number":  # refused as it is set: 0 would mean 'auto'
        with pytest.raises(ValueError, match=f"^{name} must be 'auto' or {expected}, got -1"):
            setattr(settings, name, bad)
        return
    setattr(settings, name, bad)
    with pytest.raises(ValueError, match=f"^{name} must be {expected}, got -1$"):
        settings.check()


def test_the_command_line_has_a_flag_for_each_setting_it_takes():
    from pinsettle.__main__ import SETTING_FLAGS

    flags = {f.names[0] for f in SETTING_FLAGS}
    wanted = {"--" + n.replace("_", "-") for n, f in FIELDS.items() if f["command_line"]}
    assert flags == wanted and wanted  # trace and poll settings are for programs only
    parser = argparse.ArgumentParser()
    for f in SETTING_FLAGS:
        f.add_to(parser)
    args = parser.parse_args(["--dt-safety", "auto", "--dt", "0.01", "--no-polish", "--ds", "3"])
    assert (args.dt_safety, args.dt, args.polish, args.ds) == ("auto", 0.01, False, 3)
    with pytest.raises(SystemExit):
        parser.parse_args(["--energy", "neither"])
