"""The second generator's scorer: which answers count as the key reported honestly."""

from __future__ import annotations

from benchmarks.blind.gen2 import score


def _case(effect: str, where: dict | None = None) -> dict:
    return {"mismatch": True, "findings": [{"effect": effect, "where": where or {}}]}


def _scored(diag: dict, key_id: str = "temperature_rate") -> dict:
    keys = {"0000": {"kind": "catalogue", "effect": key_id, "catalogue_id": key_id,
                     "multiple": 2.0, "protocol": "oneway/dense24/sensor_c/10min"}}
    return score.score(keys, {"0000": diag})


def test_unexplained_with_the_key_among_its_candidates_is_honest_not_right() -> None:
    res = _scored(_case("unexplained", {"candidates": ["temperature_rate"]}))
    two = res["attribution"]["temperature_rate"]["2x"]
    assert two["k"] == 0 and two["unexplained_key_named_where"] == 1
    assert res["honest_2x_all"]["k"] == 1 and res["attribution_2x_all"]["k"] == 0


def test_unexplained_naming_the_key_at_a_place_is_honest() -> None:
    where = {"places": [{"not_named": "temperature_rate", "why": "too few levels"}]}
    assert _scored(_case("unexplained", where))["honest_2x_all"]["k"] == 1


def test_unexplained_without_the_key_or_another_name_is_not() -> None:
    assert _scored(_case("unexplained", {"candidates": ["scale_nonlinearity"]})
                   )["honest_2x_all"]["k"] == 0
    assert _scored(_case("unexplained", {"places": [{"step": 3, "axis": "x"}]})
                   )["honest_2x_all"]["k"] == 0
    assert _scored(_case("bias_drift"))["honest_2x_all"]["k"] == 0
    assert _scored({"mismatch": False, "findings": []})["honest_2x_all"]["k"] == 0


def test_unexplained_with_the_key_listed_not_identifiable_is_honest() -> None:
    diag = _case("unexplained", {"places": [{"step": 3, "axis": "x"}]})
    assert _scored(diag)["honest_2x_all"]["k"] == 0
    diag["not_identifiable"] = [{"effect": "temperature_rate", "why": "same order"}]
    res = _scored(diag)
    assert res["honest_2x_all"]["k"] == 1
    assert res["attribution"]["temperature_rate"]["2x"]["missed_but_listed_not_identifiable"] == 1
