"""The regression gate: baselines, tolerance rules, comparison, JUnit XML and Markdown.

A baseline is a JSON file of aggregated values per (scene, pipeline,
sweep_param, sweep_value, metric, region, motion) with units and directions,
stamped with the suite name, config hash and machine of the run that made it.

Rules (YAML) map metric names or glob patterns to a parsed statement::

    rules:
      epe_mean: abs 0.02        # allowed worsening, in the metric's unit
      "outlier_*": abs 0.5
      "time_*": rel 10%         # allowed worsening, relative to the baseline
      track_fde: off            # not checked

An exact name wins over patterns; among patterns the first listed wins. A
rule whose name or pattern matches no registered metric is an error.
Without a rule, accuracy metrics get ``abs`` :data:`DEFAULT_ABS` and timings
``rel`` :data:`DEFAULT_REL`.

:func:`compare` is direction-aware (an improvement never fails). Timings are
checked only when the current machine equals the baseline's; otherwise they
are skipped and the result says so. A baseline from another suite, or a key
present on one side only, raises :class:`GateError` (exit code 2), never a pass; so does a
comparison with nothing in it. A failed cell in the results is a failing check (exit code 1)
even when the other seeds fill in its aggregates.

Public functions
----------------
make_baseline(results_df, run_meta) -> dict, baseline_from_run(run_dir, out_path, *, allow_failed=False) -> Path
failed_cells(results_df) -> list[dict]     the failed cells of a results table (a baseline records them)
write_baseline(baseline, path), read_baseline(path)
parse_rule(text) -> Rule, load_rules(path=None) -> dict[str, Rule], rules_from_mapping(mapping)
compare(current, baseline, rules=None, *, suite=None, machine=None) -> GateResult
    (current: DataFrame or run folder; baseline: dict or file)
to_junit_xml(result) -> str, to_markdown(result) -> str
verdict_dict(result) -> dict, write_verdict(result, path), read_verdict(path) -> dict
    the machine-readable verdict (format :data:`VERDICT_FORMAT`) that ``aerobench gate --json``
    writes and ``aerobench report --gate`` shows
change(check) -> "worse" | "better" | "within tolerance" | "skipped"
"""

from __future__ import annotations

import fnmatch
import json
import math
import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import pandas as pd
import yaml

from harness.metrics import METRICS
from harness.results import SUMMARY_KEYS, read_results, read_run_json, summarize
from scenes.formats import atomic_write_bytes

__all__ = ["GateError", "Rule", "Check", "GateResult", "BASELINE_FORMAT", "VERDICT_FORMAT", "DEFAULT_RULES",
           "DEFAULT_ABS", "DEFAULT_REL", "change", "verdict_dict", "write_verdict", "read_verdict",
           "make_baseline", "baseline_from_run", "failed_cells", "write_baseline", "read_baseline", "parse_rule", "load_rules",
           "rules_from_mapping", "compare", "to_junit_xml", "to_markdown"]

BASELINE_FORMAT = "aerobench-baseline/1"
VERDICT_FORMAT = "aerobench-gate/1"
# the tolerances of `aerobench gate` unless --rules names another file (package data)
DEFAULT_RULES = Path(__file__).resolve().parent / "gate_rules.yaml"
DEFAULT_ABS = 1e-4   # accuracy: worsening allowed in the metric's unit (px, %, deg, ...)
DEFAULT_REL = 0.20   # timings: worsening allowed relative to the baseline
KEY = (*SUMMARY_KEYS, "metric", "region", "motion")


class GateError(ValueError):
    """The gate cannot decide (missing or foreign baseline, a metric on one side only, bad rules): exit 2."""


@dataclass(frozen=True)
class Rule:
    """A tolerance: ``mode`` "abs" (in the metric's unit), "rel" (fraction of the baseline) or "off"."""

    mode: str
    tolerance: float = 0.0
    text: str = ""

    def allowed(self, baseline: float) -> float:
        return self.tolerance if self.mode == "abs" else self.tolerance * abs(baseline)

    def __str__(self) -> str:
        """The statement in its canonical form: ``abs 0.05``, ``rel 10%``, ``off`` (``(default)`` when built in)."""
        if self.mode == "off":
            text = "off"
        elif self.mode == "abs":
            text = f"abs {self.tolerance:g}"
        else:
            text = f"rel {100.0 * self.tolerance:g}%"
        return f"{text} (default)" if self.text == "default" else text

    def exceeded(self, worse: float, baseline: float) -> bool:
        """Whether a worsening of ``worse`` (in the metric's unit) goes beyond the tolerance.

        A relative 1e-9 slack absorbs float rounding: 0.0223 - 0.0123 is 0.010000000000000002 in
        binary, and a move of exactly the tolerance must pass.
        """
        allowed = self.allowed(baseline)
        return worse > allowed + 1e-9 * max(allowed, abs(baseline), 1e-3)


@dataclass
class Check:
    """One compared value."""

    key: dict
    unit: str
    higher_is_better: bool
    kind: str
    baseline: float
    current: float
    rule: Rule
    status: str  # "pass" | "fail" | "skipped"
    reason: str = ""

    @property
    def name(self) -> str:
        k = self.key
        sweep = f" {k['sweep_param']}={k['sweep_value']}" if k.get("sweep_param") else ""
        return f"{k['metric']}[{k['region']},{k['motion']}]{sweep}"

    @property
    def group(self) -> str:
        return f"{self.key['scene']}.{self.key['pipeline']}"

    @property
    def delta(self) -> float:
        return self.current - self.baseline


@dataclass
class GateResult:
    """All checks of one comparison; ``passed`` when none failed."""

    suite: str
    checks: list[Check] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def failures(self) -> list[Check]:
        return [c for c in self.checks if c.status == "fail"]

    @property
    def skipped(self) -> list[Check]:
        return [c for c in self.checks if c.status == "skipped"]

    @property
    def passed(self) -> bool:
        return not self.failures

    @property
    def exit_code(self) -> int:
        return 0 if self.passed else 1


# --------------------------------------------------------------------------- baselines

def _summary(df: pd.DataFrame) -> pd.DataFrame:
    """A summary table from either a results table (has ``frame``) or a summary already."""
    return summarize(df) if "frame" in df.columns else df


def _meta_machine(run_meta: Mapping) -> str:
    prov = run_meta.get("provenance") or {}
    return str(prov.get("machine") or run_meta.get("machine") or "")


def _meta_suite(run_meta: Mapping) -> str:
    s = run_meta.get("suite", "")
    return str(s.get("name", "")) if isinstance(s, Mapping) else str(s)


def failed_cells(results_df: pd.DataFrame) -> list[dict]:
    """The failed cells of a results table, one dict each: ``cell_id, scene, seed, pipeline, sweep_param,
    sweep_value, error`` (strings; seed an int), in table order; empty for a summary table."""
    if "status" not in results_df.columns:
        return []
    bad = results_df[results_df["status"] != "ok"]
    if "cell_id" in bad.columns:
        bad = bad.drop_duplicates("cell_id")
    out = []
    for r in bad.to_dict("records"):
        seed = r.get("seed")
        out.append({"cell_id": str(r.get("cell_id", "")), "scene": str(r.get("scene", "")),
                    "seed": int(seed) if seed is not None and not pd.isna(seed) else None,
                    "pipeline": str(r.get("pipeline", "")), "sweep_param": str(r.get("sweep_param") or ""),
                    "sweep_value": str(r.get("sweep_value") or ""), "error": str(r.get("error") or "no result")})
    return out


def _cell_words(cell: Mapping) -> str:
    sweep = f" {cell['sweep_param']}={cell['sweep_value']}" if cell.get("sweep_param") and \
        f"{cell['sweep_param']}=" not in cell["scene"] else ""
    return f"{cell['scene']}{sweep} seed {cell['seed']} x {cell['pipeline']}: {cell['error']}"


def make_baseline(results_df: pd.DataFrame, run_meta: Mapping) -> dict:
    """A baseline from a run's results (or summary) and its run.json contents.

    ``run_meta`` keys used: ``suite`` (name), ``config_hash``, ``provenance.machine``
    (or ``machine``), ``provenance.git_commit``. For a run folder, see
    :func:`baseline_from_run`. The run's failed cells (:func:`failed_cells`) are recorded
    under ``failed_cells``: their metrics are not in the baseline.
    """
    if not isinstance(run_meta, Mapping):
        raise TypeError(f"make_baseline(results_df, run_meta): run_meta must be the run.json dict, got "
                        f"{type(run_meta).__name__}; to write the baseline of a run folder use "
                        "gate.baseline_from_run(run_dir, out_path)")
    if not isinstance(results_df, pd.DataFrame):
        raise TypeError(f"make_baseline: results_df must be a DataFrame, got {type(results_df).__name__}")
    suite = _meta_suite(run_meta)
    if not suite:
        raise GateError("run metadata has no suite name: cannot make a baseline")
    s = _summary(results_df)
    entries = []
    for r in s.sort_values(list(KEY)).itertuples(index=False):
        d = r._asdict()
        entries.append({**{k: str(d[k]) for k in KEY}, "value": _num(d["value"]), "unit": d["unit"],
                        "higher_is_better": bool(d["higher_is_better"]), "kind": d["kind"],
                        "count": _num(d["count"])})
    return {"format": BASELINE_FORMAT, "suite": suite, "config_hash": str(run_meta.get("config_hash", "")),
            "machine": _meta_machine(run_meta),
            "git_commit": str((run_meta.get("provenance") or {}).get("git_commit", "")),
            "created": datetime.now(timezone.utc).isoformat(timespec="seconds"), "metrics": entries,
            "failed_cells": failed_cells(results_df)}


def baseline_from_run(run_dir: str | os.PathLike, out_path: str | os.PathLike, *,
                      allow_failed: bool = False) -> Path:
    """Read a run folder (results.parquet + run.json), make its baseline and write it to ``out_path``.

    A run with a failed cell is refused (:class:`GateError` naming the cells): its baseline would
    silently lack that cell's metrics. ``allow_failed`` writes it anyway, the cells recorded in it.
    """
    results = read_results(run_dir)
    failed = failed_cells(results)
    if failed and not allow_failed:
        raise GateError(f"{run_dir}: {len(failed)} cell(s) failed, so the baseline would lack their metrics: "
                        + "; ".join(_cell_words(c) for c in failed[:5]) + (" ..." if len(failed) > 5 else "")
                        + "; re-run them (aerobench run SUITE --out RUN --resume), or pass --allow-failed")
    return write_baseline(make_baseline(results, read_run_json(run_dir)), out_path)


def _num(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def write_baseline(baseline: Mapping, path: str | os.PathLike) -> Path:
    """Write a baseline as indented JSON, atomically (NaN is written as null)."""
    path = Path(path)
    atomic_write_bytes(path, (json.dumps(baseline, indent=1, sort_keys=True, allow_nan=False) + "\n").encode())
    return path


def read_baseline(path: str | os.PathLike) -> dict:
    """Read a baseline; a missing, unreadable or foreign file raises :class:`GateError`."""
    return _read_format_json(path, what="baseline", fmt=BASELINE_FORMAT,
                             missing="no baseline file; make one with `aerobench baseline` (a missing baseline "
                                     "is an error, not a pass)")


def _read_format_json(path: str | os.PathLike, *, what: str, fmt: str, missing: str) -> dict:
    """A JSON object whose ``format`` is ``fmt``; anything else raises :class:`GateError` naming the file."""
    path = Path(path)
    if not path.is_file():
        raise GateError(f"{path}: {missing}")
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise GateError(f"{path}: {what} is not valid JSON: {exc}") from None
    if not isinstance(data, dict) or data.get("format") != fmt:
        got = data.get("format") if isinstance(data, dict) else type(data).__name__
        raise GateError(f"{path}: not an aerobench {what}: format {got!r}, expected {fmt!r}")
    return data


# --------------------------------------------------------------------------- rules

_RULE = re.compile(r"^\s*(abs|rel)\s+([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*(%?)\s*$")


def parse_rule(text: str) -> Rule:
    """Parse ``"abs 0.02"``, ``"rel 10%"`` (or ``"rel 0.1"``) or ``"off"``."""
    t = str(text).strip()
    if t.lower() == "off":
        return Rule("off", 0.0, t)
    m = _RULE.match(t)
    if not m:
        raise GateError(f"rule {text!r}: expected 'abs <number>', 'rel <number>%' or 'off'")
    mode, num, pct = m.group(1), float(m.group(2)), m.group(3)
    if pct and mode == "abs":
        raise GateError(f"rule {text!r}: a percentage is relative; write 'rel {m.group(2)}%'")
    return Rule(mode, num / 100.0 if pct else num, t)


def rules_from_mapping(mapping: Mapping, *, source: str = "rules") -> dict[str, Rule]:
    """Parse ``{name or pattern: statement}``; a name matching no registered metric is an error."""
    out = {}
    for name, text in mapping.items():
        name = str(name)
        if not any(fnmatch.fnmatchcase(m, name) for m in METRICS):
            raise GateError(f"{source}: rule {name!r} names no metric; valid: {', '.join(sorted(METRICS))}")
        try:
            out[name] = parse_rule(text)
        except GateError as exc:
            raise GateError(f"{source}: {name}: {exc}") from None
    return out


def load_rules(path: str | os.PathLike | None = None) -> dict[str, Rule]:
    """Read gate rules from YAML: a mapping under ``rules:`` (or at the top level).

    Without a path: no rules, so every metric gets the defaults.
    """
    if path is None:
        return {}
    path = Path(path)
    if not path.is_file():
        raise GateError(f"{path}: no such rules file")
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as exc:
        raise GateError(f"{path}: not valid YAML: {exc}") from None
    if isinstance(data, Mapping) and "rules" in data:
        extra = set(data) - {"rules"}
        if extra:
            raise GateError(f"{path}: unknown key(s) {sorted(extra)}; expected only 'rules'")
        data = data["rules"] or {}
    if not isinstance(data, Mapping):
        raise GateError(f"{path}: expected a mapping of metric -> rule, got {type(data).__name__}")
    return rules_from_mapping(data, source=str(path))


def _rule_for(metric: str, kind: str, rules: Mapping[str, Rule]) -> Rule:
    if metric in rules:
        return rules[metric]
    for pattern, rule in rules.items():
        if fnmatch.fnmatchcase(metric, pattern):
            return rule
    return Rule("rel", DEFAULT_REL, "default") if kind == "timing" else Rule("abs", DEFAULT_ABS, "default")


# --------------------------------------------------------------------------- compare

def compare(current: pd.DataFrame | str | os.PathLike, baseline: Mapping | str | os.PathLike, rules: Mapping[str, Rule] | None = None, *,
            suite: str | None = None, machine: str | None = None) -> GateResult:
    """Check current results against a baseline.

    Parameters
    ----------
    current : DataFrame or path
        A results table (summarised here), a summary from :func:`harness.results.summarize`,
        or a run folder (its results and, unless ``suite`` is given, its run.json suite name).
    baseline : dict or path
        From :func:`read_baseline` / :func:`make_baseline`, or the baseline file.
    rules : dict, optional
        From :func:`load_rules`.
    suite : str, optional
        The current suite's name; must equal the baseline's.
    machine : str, optional
        The current machine id; default the ``machine`` column of a results table.

    Raises
    ------
    GateError
        Baseline from another suite, or a (scene, pipeline, sweep, metric, region,
        motion) present on one side only.
    """
    rules = dict(rules or {})
    if not isinstance(current, pd.DataFrame):
        run_dir = Path(current)
        current = read_results(run_dir)
        if suite is None:
            suite = _meta_suite(read_run_json(run_dir))
    if not isinstance(baseline, Mapping):
        baseline = read_baseline(baseline)
    if baseline.get("format") != BASELINE_FORMAT:
        raise GateError(f"not an aerobench baseline (format {baseline.get('format')!r})")
    base_suite = str(baseline.get("suite", ""))
    if suite is not None and suite != base_suite:
        raise GateError(f"baseline is for suite {base_suite!r}, the results are of suite {suite!r}")
    if machine is None and "machine" in current.columns:
        ms = sorted(set(current["machine"].astype(str)))
        machine = ms[0] if len(ms) == 1 else None
    result = GateResult(suite=base_suite)
    s = _summary(current)
    cur = {tuple(str(r[k]) for k in KEY): r for r in s.to_dict("records")}
    base = {tuple(str(e[k]) for k in KEY): e for e in baseline.get("metrics", [])}
    only_cur, only_base = sorted(set(cur) - set(base)), sorted(set(base) - set(cur))
    if only_cur or only_base:
        def fmt(keys):
            return "; ".join("/".join(k) for k in keys[:10]) + (" ..." if len(keys) > 10 else "")
        msg = []
        if only_base:
            msg.append(f"{len(only_base)} in the baseline but not in the results: {fmt(only_base)}")
        if only_cur:
            msg.append(f"{len(only_cur)} in the results but not in the baseline: {fmt(only_cur)}")
        if "status" in current.columns and (current["status"] != "ok").any():
            bad = current[current["status"] != "ok"].drop_duplicates("cell_id")
            msg.append(f"{len(bad)} cell(s) failed: " + "; ".join(
                f"{r.scene}/{r.pipeline}: {r.error}" for r in bad.head(5).itertuples()))
        if baseline.get("failed_cells"):
            msg.append(_allow_failed_note(baseline))
        raise GateError("metrics on one side only (re-make the baseline if the suite changed): " + " | ".join(msg))
    if not base and not cur:
        raise GateError("nothing to compare: neither the baseline nor the results hold a metric")
    same_machine = bool(machine) and machine == baseline.get("machine")
    if not same_machine:
        result.notes.append(f"timings skipped: baseline machine {baseline.get('machine')!r}, "
                            f"current machine {machine!r}")
    if suite is None:
        result.notes.append("suite name not given: not checked against the baseline's")
    if baseline.get("failed_cells"):
        result.notes.append(_allow_failed_note(baseline))
    for k in sorted(base):
        b, c = base[k], cur[k]
        key = dict(zip(KEY, k))
        kind = str(b.get("kind", "accuracy"))
        hib = bool(b["higher_is_better"])
        bv = float("nan") if b["value"] is None else float(b["value"])
        cv = float(c["value"])
        rule = _rule_for(key["metric"], kind, rules)
        status, reason = "pass", ""
        if rule.mode == "off":
            status, reason = "skipped", "rule off"
        elif kind == "timing" and not same_machine:
            status, reason = "skipped", "timing on another machine"
        elif math.isnan(bv) and math.isnan(cv):
            reason = "no value on either side"
        elif math.isnan(bv) or math.isnan(cv):
            status, reason = "fail", "value missing (NaN) on one side"
        else:
            worse = (bv - cv) if hib else (cv - bv)
            if rule.exceeded(worse, bv):
                status = "fail"
                reason = (f"{'fell' if hib else 'rose'} by {abs(cv - bv):.6g} {b['unit']}, allowed "
                          f"{rule.allowed(bv):.6g} {b['unit']} ({rule})")
        result.checks.append(Check(key, str(b["unit"]), hib, kind, bv, cv, rule, status, reason))
    # A failed cell leaves no rows, so its scene/pipeline aggregate silently comes from the other
    # seeds (or sweep values): the keys still match and every value may pass. Never a pass.
    if "status" in current.columns and (current["status"] != "ok").any():
        bad = current[current["status"] != "ok"].drop_duplicates("cell_id" if "cell_id" in current else None)
        for r in bad.to_dict("records"):
            key = {k: str(r.get(k, "")) for k in KEY}
            key.update(metric="cell_failed", region="all", motion="cell")
            result.checks.append(Check(key, "", False, "accuracy", math.nan, math.nan, Rule("abs", 0.0, "failed cell"),
                                       "fail", f"cell {r.get('cell_id', '')} seed {r.get('seed', '')} failed: "
                                               f"{r.get('error', '') or 'no result'}"))
    return result


def _allow_failed_note(baseline: Mapping) -> str:
    cells = baseline.get("failed_cells") or []
    return (f"the baseline was made with --allow-failed from a run with {len(cells)} failed cell(s), whose metrics "
            "are not in it: " + "; ".join(_cell_words(c) for c in cells[:5]) + (" ..." if len(cells) > 5 else ""))


# --------------------------------------------------------------------------- reports

def _value(x: float) -> str:
    """A compared value for a table: ``n/a`` where there is none (never ``nan``)."""
    return "n/a" if math.isnan(x) else f"{x:.6g}"


def _is_failed_cell(c: Check) -> bool:
    return c.key.get("metric") == "cell_failed"


def _describe(c: Check) -> str:
    if _is_failed_cell(c):
        return f"{c.group}: {c.reason}"
    return (f"{c.group} {c.name}: baseline {_value(c.baseline)} {c.unit}, current {_value(c.current)} {c.unit} "
            f"({'higher' if c.higher_is_better else 'lower'} is better): {c.reason}")


def to_junit_xml(result: GateResult) -> str:
    """JUnit XML: one testsuite, one testcase per checked metric (failure / skipped elements)."""
    suite = ET.Element("testsuite", name=f"aerobench-gate.{result.suite}", tests=str(len(result.checks)),
                       failures=str(len(result.failures)), errors="0", skipped=str(len(result.skipped)))
    if result.notes:
        props = ET.SubElement(suite, "properties")
        for i, n in enumerate(result.notes):
            ET.SubElement(props, "property", name=f"note{i}", value=n)
    for c in result.checks:
        tc = ET.SubElement(suite, "testcase", classname=c.group, name=c.name)
        if c.status == "fail":
            f = ET.SubElement(tc, "failure", message=c.reason, type="regression")
            f.text = _describe(c)
        elif c.status == "skipped":
            ET.SubElement(tc, "skipped", message=c.reason)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(suite, encoding="unicode") + "\n"


def to_markdown(result: GateResult) -> str:
    """A Markdown page for a CI job: verdict, notes, the violations table, counts."""
    n, nf, ns = len(result.checks), len(result.failures), len(result.skipped)
    head = "PASS" if result.passed else "FAIL"
    lines = [f"## aerobench gate: {head} ({result.suite})", "",
             f"{n} checked, {n - nf - ns} passed, {nf} failed, {ns} skipped.", ""]
    lines += [f"- {note}" for note in result.notes]
    if result.notes:
        lines.append("")
    cells = [c for c in result.failures if _is_failed_cell(c)]
    values = [c for c in result.failures if not _is_failed_cell(c)]
    if cells:
        lines += ["Failed cells (a failed cell is never a pass):", ""]
        lines += [f"- {c.key['scene']} / {c.key['pipeline']}: cell failed: {c.reason.partition(' failed: ')[2]}"
                  for c in cells]
        lines.append("")
    if values:
        lines += ["| scene | pipeline | metric | baseline | current | change | allowed | unit |",
                  "|---|---|---|---:|---:|---:|---|---|"]
        for c in values:
            change = "n/a" if math.isnan(c.delta) else f"{c.delta:+.6g}"
            lines.append(f"| {c.key['scene']} | {c.key['pipeline']} | {c.name} | {_value(c.baseline)} | "
                         f"{_value(c.current)} | {change} | {c.rule} | {c.unit} |")
        lines.append("")
    return "\n".join(lines)



# --------------------------------------------------------------------------- machine-readable verdict

def change(check: Check) -> str:
    """How ``check`` moved by the gate's own rule: "worse" (beyond the tolerance: the check fails),
    "better" (improved by more than the tolerance), "within tolerance", or "skipped"."""
    if check.status == "skipped":
        return "skipped"
    if check.status == "fail":
        return "worse"
    if math.isnan(check.baseline) or math.isnan(check.current):
        return "within tolerance"
    better = (check.current - check.baseline) if check.higher_is_better else (check.baseline - check.current)
    return "better" if check.rule.exceeded(better, check.baseline) else "within tolerance"


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def verdict_dict(result: GateResult) -> dict:
    """The verdict as plain data: ``format`` (:data:`VERDICT_FORMAT`), ``suite``, ``passed``, ``exit_code``,
    ``counts`` (checked, passed, failed, skipped), ``notes`` and one entry per check (key fields,
    unit, direction, baseline, current, rule, status, change, reason; NaN as null)."""
    checks = []
    for c in result.checks:
        checks.append({**c.key, "unit": c.unit, "higher_is_better": c.higher_is_better, "kind": c.kind,
                       "baseline": _finite(c.baseline), "current": _finite(c.current), "rule": str(c.rule),
                       "status": c.status, "change": change(c), "reason": c.reason})
    n, nf, ns = len(result.checks), len(result.failures), len(result.skipped)
    return {"format": VERDICT_FORMAT, "suite": result.suite, "passed": result.passed, "exit_code": result.exit_code,
            "counts": {"checked": n, "passed": n - nf - ns, "failed": nf, "skipped": ns},
            "notes": list(result.notes), "checks": checks}


def write_verdict(result: GateResult, path: str | os.PathLike) -> Path:
    """Write :func:`verdict_dict` as JSON, atomically."""
    path = Path(path)
    atomic_write_bytes(path, (json.dumps(verdict_dict(result), indent=1, allow_nan=False) + "\n").encode())
    return path


def read_verdict(path: str | os.PathLike) -> dict:
    """Read a verdict written by :func:`write_verdict`; a missing or foreign file raises :class:`GateError`."""
    return _read_format_json(path, what="gate verdict", fmt=VERDICT_FORMAT,
                             missing=f"no gate verdict file; write one with `aerobench gate RUN --baseline B "
                                     f"--json {path}`")
