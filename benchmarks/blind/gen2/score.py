"""Score diagnoses of the second generator's cases against its keys (after all ran)."""

from __future__ import annotations

from collections import defaultdict
from typing import Any

from benchmarks.blind.score import clopper_pearson
from calibration.discrepancy.effects import BY_ID

BEYOND = {"unexplained", "not_identifiable", "parameter_shift"}


def _rate(k: int, n: int) -> dict[str, Any]:
    lo, hi = clopper_pearson(k, n)
    return {"k": k, "n": n, "rate": k / n if n else None, "ci95": [lo, hi]}


def _named(d: dict) -> list[str]:
    return [f.get("effect") for f in d.get("findings") or []]


def _not_separable(d: dict, key_id: str) -> bool:
    """The top finding is ``not_identifiable`` with the key among its candidates: the
    effect was seen and honestly reported as not separable from its rival(s)."""
    first = (d.get("findings") or [{}])[0]
    return first.get("effect") == "not_identifiable" and key_id in (
        (first.get("where") or {}).get("candidates") or [])


def _not_confirmed(d: dict, key_id: str) -> bool:
    """The top finding is ``unexplained`` and names the key where it is: among the
    candidates (structure the family test found and held-out data did not confirm), or as
    a term withheld at one of its places with the reason (too few input levels, say). The
    effect was seen and reported as not established, with the reason: no wrong name."""
    first = (d.get("findings") or [{}])[0]
    if first.get("effect") != "unexplained":
        return False
    where = first.get("where") or {}
    named = set(where.get("candidates") or [])
    named |= {p.get("not_named") for p in where.get("places") or [] if isinstance(p, dict)}
    return key_id in named


def _flagged(d: dict) -> bool:
    return bool(d.get("mismatch")) or bool(d.get("findings"))


def fired_tests(d: dict) -> list[dict[str, Any]]:
    """Which of ``diagnose``'s tests made this recording a "mismatch", with p and level.

    The verdict is the union of two tests, each at α/2 (docs/diagnosis.md §8): the forward
    selection's family test (every named finding, ``not_identifiable`` and ``outlier``
    included, and an ``unexplained`` finding whose term a physics check withdrew) and the
    localised scan (an ``unexplained`` finding). The χ² excess test is reported beside
    them; it does not enter the verdict (``excess_chi2`` says whether it was significant).
    """
    alpha = float((d.get("null") or {}).get("alpha") or 0.01)
    out: list[dict[str, Any]] = []
    stage = 0
    for f in d.get("findings") or []:
        ev = f.get("evidence") or {}
        test = str(ev.get("test") or "")
        if f.get("effect") == "unexplained" and test.startswith("localised scan"):
            kind, at = "scan", None
        else:
            stage += 1
            kind = ("family test, withdrawn by a physics check" if "physics check" in test
                    else "family test")
            at = stage
        where = f.get("where") or {}
        out.append({"test": kind, "effect": f.get("effect"), "stage": at,
                    "candidates": where.get("candidates"), "p": ev.get("p_value"),
                    "level": alpha / 2})
    chi = (d.get("unexplained") or {}).get("chi_square") or {}
    if chi.get("significant"):
        out.append({"test": "excess chi2 (reported, not in the verdict)", "effect": None,
                    "stage": None, "p": chi.get("p_value"), "level": alpha})
    return out


def score(keys: dict[str, dict], diags: dict[str, dict]) -> dict[str, Any]:
    res: dict[str, Any] = {"errors": sorted(c for c, d in diags.items() if "error" in d)}
    nulls = [c for c, k in keys.items() if k["kind"] == "null"]
    fa = [c for c in nulls if _flagged(diags[c])]
    by_kind: dict[str, list[int]] = defaultdict(lambda: [0, 0])
    for c in nulls:
        kind = keys[c]["protocol"].split("/")[0] + "/" + keys[c]["protocol"].split("/")[1]
        by_kind[kind][1] += 1
        by_kind[kind][0] += _flagged(diags[c])
    res["false_alarms"] = {**_rate(len(fa), len(nulls)), "by_protocol": dict(by_kind),
                           "named": sorted({e for c in fa for e in _named(diags[c])}),
                           "cases": sorted(fa),
                           "fired": {c: {"protocol": keys[c]["protocol"],
                                         "tests": fired_tests(diags[c])} for c in sorted(fa)},
                           "by_test": _by_test(fa, diags)}
    attrib: dict[str, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    for c, k in keys.items():
        if k["kind"] != "catalogue":
            continue
        top = (_named(diags[c]) or [None])[0]
        listed = {n.get("effect") for n in diags[c].get("not_identifiable") or []}
        attrib[k["effect"]][f"{k['multiple']:g}x"].append(
            {"case": c, "top": top, "right": top == k["catalogue_id"],
             "among": k["catalogue_id"] in _named(diags[c]),
             # an honest miss: nothing named, or only structure left unexplained, and the
             # effect listed as not identifiable under this protocol (with the experiment)
             "listed": top in (None, "unexplained") and k["catalogue_id"] in listed,
             "not_separable": _not_separable(diags[c], k["catalogue_id"]),
             "not_confirmed": _not_confirmed(diags[c], k["catalogue_id"]),
             "wrong": top is not None and top != k["catalogue_id"] and top not in BEYOND})
    res["attribution"] = {
        eid: {m: {**_rate(sum(r["right"] for r in rs), len(rs)),
                  "among_findings": sum(r["among"] for r in rs),
                  "missed_but_listed_not_identifiable": sum(r["listed"] for r in rs),
                  "wrong_catalogue_name": sum(r["wrong"] for r in rs),
                  "not_separable_key_among_candidates": sum(r["not_separable"] for r in rs),
                  "unexplained_key_named_where": sum(r["not_confirmed"] for r in rs),
                  "named": [r["top"] for r in rs]} for m, rs in sorted(ms.items())}
        for eid, ms in sorted(attrib.items())}
    two = [r for ms in attrib.values() for r in ms.get("2x", [])]
    res["attribution_2x_all"] = _rate(sum(r["right"] for r in two), len(two))
    # Right, or the key reported as not established with its reason (not separable, listed
    # not identifiable, unexplained with the key named where it is) and no wrong name: the
    # answers a lab engineer would not have to correct. The rest: a wrong name or a miss.
    res["honest_2x_all"] = _rate(sum(r["right"] or r["not_separable"] or r["listed"]
                                     or r["not_confirmed"] for r in two), len(two))
    hidden = [c for c, k in keys.items() if k["kind"] == "hidden"]
    res["hidden_named"] = _rate(sum(keys[c]["catalogue_id"] in _named(diags[c])
                                    for c in hidden), len(hidden))
    outs = [c for c, k in keys.items() if k["kind"] == "outside"]
    cat = [c for c in outs if any(e in BY_ID and e not in BEYOND for e in _named(diags[c]))]
    res["outside_given_catalogue_name"] = {
        **_rate(len(cat), len(outs)),
        "by_effect": {e: [[_named(diags[c]) for c in outs if keys[c]["effect"] == e]]
                      for e in sorted({keys[c]["effect"] for c in outs})},
        "rate_by_effect": {e: _rate(sum(c in cat for c in outs if keys[c]["effect"] == e),
                                    sum(keys[c]["effect"] == e for c in outs))
                           for e in sorted({keys[c]["effect"] for c in outs})},
        "cases": {c: {"effect": keys[c]["effect"], "protocol": keys[c].get("protocol"),
                      "named": _named(diags[c])} for c in sorted(cat)}}
    tw = [c for c, k in keys.items() if k["kind"] == "against"]
    rows = []
    for c in tw:
        d, k = diags[c], keys[c]
        shift = [f for f in d.get("findings") or [] if f.get("effect") == "parameter_shift"]
        names = sorted((shift[0].get("parameters") or {}) if shift else [])
        if k["change"] == "unchanged":
            right = not shift
        else:
            right = bool(shift) and any("_mz" in n for n in names) and not any(
                n.startswith(("d_bx", "d_by", "d_bz")) for n in names)
        rows.append({"case": c, "change": k["change"], "right": right, "shifted": names,
                     "protocol": k["protocol"]})
    res["against"] = {**_rate(sum(r["right"] for r in rows), len(rows)),
                      "unchanged_with_shift": sum(r["change"] == "unchanged" and not r["right"]
                                                  for r in rows),
                      "by_change": {ch: _rate(sum(r["right"] for r in rows if r["change"] == ch),
                                              sum(r["change"] == ch for r in rows))
                                    for ch in ("unchanged", "remount_z")},
                      "cases": rows}
    return res


def _by_test(cases: list[str], diags: dict[str, dict]) -> dict[str, int]:
    """Flagged cases per test that fired (a case counts once per test kind)."""
    out: dict[str, int] = defaultdict(int)
    for c in cases:
        kinds = {t["test"] + (f" ({t['effect']})" if t["test"].startswith("family") else "")
                 for t in fired_tests(diags[c]) if "verdict" not in t["test"]}
        for k in kinds:
            out[k] += 1
    return dict(sorted(out.items()))


def _pct(r: dict) -> str:
    if not r["n"]:
        return "–"
    lo, hi = r["ci95"]
    return f"{r['k']}/{r['n']} = {100 * r['rate']:.1f} % (95 % CI {100 * lo:.1f}–{100 * hi:.1f})"


def markdown(res: dict, header: str) -> str:
    out = [header, "", f"* false alarms on nulls: {_pct(res['false_alarms'])}; named: "
           f"{', '.join(res['false_alarms']['named']) or '–'}",
           f"* attribution at 2× (top finding = key), all effects: "
           f"{_pct(res['attribution_2x_all'])}; right or the key reported not established "
           f"with its reason: {_pct(res['honest_2x_all'])}",
           f"* outside-catalogue effects given a catalogue name: "
           f"{_pct(res['outside_given_catalogue_name'])}",
           f"* twin against recording right: {_pct(res['against'])} "
           f"(unchanged sensor given a parameter_shift: {res['against']['unchanged_with_shift']})",
           f"* hidden (undetectable under the drawn protocol) named anyway: "
           f"{_pct(res['hidden_named'])}", f"* crashes: {len(res['errors'])}", "",
           "| effect | 1× right | 2× right | 2× named | 2× wrong name | 2× missed or "
           "unexplained, listed not identifiable | 2× not separable, key among the "
           "candidates | 2× unexplained, key named where it is |",
           "|---|---|---|---|---|---|---|---|"]
    for eid, ms in res["attribution"].items():
        one, two = ms.get("1x"), ms.get("2x")
        out.append(f"| {eid} | {one['k'] if one else 0}/{one['n'] if one else 0} | "
                   f"{two['k'] if two else 0}/{two['n'] if two else 0} | "
                   f"{', '.join(str(x) for x in two['named']) if two else ''} | "
                   f"{two['wrong_catalogue_name'] if two else ''} | "
                   f"{two['missed_but_listed_not_identifiable'] if two else ''} | "
                   f"{two.get('not_separable_key_among_candidates', '') if two else ''} | "
                   f"{two.get('unexplained_key_named_where', '') if two else ''} |")
    out += ["", "| null protocol | flagged / n |", "|---|---|"]
    for k, (f, n) in sorted(res["false_alarms"]["by_protocol"].items()):
        out.append(f"| {k} | {f}/{n} |")
    fa = res["false_alarms"]
    if fa.get("fired"):
        out += ["", "| flagged null | protocol | test fired (stage, effect): p at level |",
                "|---|---|---|"]
        for c, v in fa["fired"].items():
            tests = "; ".join(
                f"{t['test']}" + (f" (stage {t['stage']}, {t['effect']})" if t["stage"] else "")
                + (f" {t['candidates']}" if t.get("candidates") else "")
                + f": p = {t['p']} at {t['level']:g}" for t in v["tests"])
            out.append(f"| {c} | {v['protocol']} | {tests} |")
        out += ["", "flagged nulls per test: " + ", ".join(
            f"{k} {n}" for k, n in fa["by_test"].items())]
    out += ["", "| outside effect | given a catalogue name | findings per case |", "|---|---|---|"]
    rates = res["outside_given_catalogue_name"].get("rate_by_effect", {})
    for e, v in res["outside_given_catalogue_name"]["by_effect"].items():
        out.append(f"| {e} | {_pct(rates[e]) if e in rates else ''} | {v[0]} |")
    return "\n".join(out) + "\n"
