"""Read a ``soakcal diagnose --json`` document into what the gen3 report needs (issue 22):
the verdict and, per finding, the effect, the test that fired (family, outlier, scan) and
its family-wise p."""

from __future__ import annotations

from typing import Any


def _first_key(doc: Any, names: tuple[str, ...]) -> Any:
    """The first value under any of ``names`` in a nested dict/list, depth first."""
    if isinstance(doc, dict):
        for name in names:
            if name in doc:
                return doc[name]
        for v in doc.values():
            found = _first_key(v, names)
            if found is not None:
                return found
    elif isinstance(doc, list):
        for v in doc:
            found = _first_key(v, names)
            if found is not None:
                return found
    return None


def test_kind(finding: dict[str, Any], scan_significant: bool) -> str:
    effect = finding.get("effect")
    if effect == "outlier":
        return "outlier"
    if effect == "unexplained" and scan_significant:
        return "scan"
    return "family"


def summarise(doc: dict[str, Any]) -> dict[str, Any]:
    """mismatch, verdict, baseline and per finding {effect, test, p_family, axes, where}."""
    unexplained = doc.get("unexplained") or {}
    scan = bool(unexplained.get("significant"))
    chi = unexplained.get("chi_square") or {}
    findings = []
    for f in doc.get("findings", []):
        findings.append({
            "effect": f.get("effect"), "test": test_kind(f, scan),
            # the JSON's evidence p is the family-wise one (min-p over the candidates
            # against its null); a nested p_family is read where a finding carries one
            "p_family": _first_key(f, ("p_family",))
            or _first_key(f.get("evidence", {}), ("p_value",)),
            "p_value": _first_key(f.get("evidence", {}), ("p_value",)),
            "evidence_test": (f.get("evidence") or {}).get("test"),
            "axes": f.get("axes"), "where": f.get("where"),
            "explanation": f.get("explanation")})
    return {
        "mismatch": doc.get("mismatch"), "verdict": doc.get("verdict"),
        "reason": doc.get("reason"),
        "baseline_rmse_ug": (doc.get("baseline") or {}).get("rmse_ug"),
        "baseline_noise_ug": (doc.get("baseline") or {}).get("noise_ug"),
        "scan_significant": scan, "scan_p": unexplained.get("p_value"),
        "chi2_per_dof": chi.get("chi2_per_dof"), "chi2_significant": chi.get("significant"),
        "findings": findings,
    }
