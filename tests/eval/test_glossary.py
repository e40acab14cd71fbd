"""The one table of labels, units and explanations that the console and the report share."""

from __future__ import annotations

import math

import pytest

from slamkit.eval.glossary import GROUPS, METRICS, describe, metric_rows


def _rows(metrics: dict) -> dict:
    return {r.info.key: r for r in metric_rows(metrics)}


def test_the_table_is_one_entry_a_key_each_with_a_group_and_an_explanation() -> None:
    keys = [m.key for m in METRICS]
    assert len(keys) == len(set(keys))
    assert all(m.group in GROUPS for m in METRICS)
    assert all(m.explanation for m in METRICS if m.console)


def test_radians_are_shown_in_degrees_and_fractions_in_per_cent() -> None:
    rows = _rows(
        {
            "ate_unaligned": {"heading_rmse": math.radians(2.0), "mean": 0.25},
            "rpe_1_step": {"rotation_max": math.radians(30.0)},
            "nees": {"fraction_in_band": 0.9512},
            "relations": {"rotation_mean_deg": 1.25, "rotation_std_deg": 0.5},
        }
    )
    heading = rows["ate_unaligned.heading_rmse"]
    assert heading.info.unit == "deg" and heading.text == "2.00" and heading.named
    assert heading.value == pytest.approx(2.0)
    assert heading.info.heading == "heading RMSE, unaligned [deg]"
    # not named in the table: unit and group from its record and name
    rot = rows["rpe_1_step.rotation_max"]
    assert rot.info.unit == "deg" and rot.value == pytest.approx(30.0) and not rot.named
    assert rot.info.group == "accuracy against the truth"
    assert rows["ate_unaligned.mean"].info.unit == "m"
    assert rows["nees.fraction_in_band"].text == "95.1"
    # a key already in degrees is not converted again; its spread is shown with it
    assert rows["relations.rotation_mean_deg"].text == "1.2 ± 0.5"
    assert "relations.rotation_std_deg" not in rows


def test_a_record_that_does_not_apply_is_one_named_row_and_page_keys_are_left_out() -> None:
    rows = _rows({"estimator": "x", "gps": {"skipped": "no fix"}, "warnings": [], "seed": 4})
    assert rows["gps"].text == "skipped: no fix" and rows["gps"].named
    assert rows["seed"].text == "4" and rows["seed"].info.group == "the run"
    assert "estimator" not in rows and "warnings" not in rows


def test_an_unknown_key_still_gets_a_label() -> None:
    info = describe("mystery.thing_s")
    assert info.label == "mystery, thing s" and info.unit == "s"
