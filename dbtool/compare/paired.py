"""Paired differences of the comparison (docs/results.md): per task, DiffuseBot's metric minus
each other method's on the same seed, their mean with a 95% interval over seeds (Student's t,
``n - 1`` degrees of freedom), and a verdict per task in words."""

from __future__ import annotations

import math

from scipy import stats

from dbtool.choices import METHODS
from dbtool.compare.labels import method_name, ordered, task_title
from dbtool.sim.task_names import NAMES as TASKS

LEVEL = 0.95


def paired_differences(rows: list[dict], method: str = "diffusebot") -> list[dict]:
    """One entry per (task, other method) with at least one seed done by both: the seeds,
    the per-seed differences ``method - other``, their mean, sample sd and 95% interval
    (None for one seed), and ``sign``: ``+1`` (interval above 0), ``-1`` (below) or 0."""
    done = {(r["method"], r["task"], int(r["seed"])): float(r["metric"]) for r in rows
            if r.get("status") == "done" and math.isfinite(float(r["metric"]))}
    tasks = ordered({t for _, t, _ in done}, TASKS)
    others = [m for m in ordered({m for m, _, _ in done}, METHODS) if m != method]
    out = []
    for task in tasks:
        for other in others:
            seeds = sorted(s for m, t, s in done if m == method and t == task
                           and (other, task, s) in done)
            if not seeds:
                continue
            d = [done[method, task, s] - done[other, task, s] for s in seeds]
            n, mean = len(d), sum(d) / len(d)
            sd = math.sqrt(sum((x - mean) ** 2 for x in d) / (n - 1)) if n > 1 else None
            lo = hi = None
            if sd is not None:
                half = stats.t.ppf(0.5 + LEVEL / 2, n - 1) * sd / math.sqrt(n)
                lo, hi = mean - half, mean + half
            sign = 0 if lo is None else (1 if lo > 0 else -1 if hi < 0 else 0)
            out.append({"task": task, "method": method, "other": other, "seeds": seeds,
                        "differences": d, "n": n, "mean": mean, "sd": sd, "lo": lo, "hi": hi,
                        "sign": sign})
    return out


def verdict(diffs: list[dict], task: str) -> str:
    """The task's verdict in words from its paired differences."""
    mine = [d for d in diffs if d["task"] == task]
    if not mine:
        return f"{task_title(task)}: no seed done by DiffuseBot and another method."
    name = method_name(mine[0]["method"])
    group = {s: [method_name(d["other"]) for d in mine if d["sign"] == s and d["lo"] is not None]
             for s in (1, -1, 0)}
    single = [method_name(d["other"]) for d in mine if d["lo"] is None]
    n = sorted({d["n"] for d in mine})
    seeds = f"{n[0]}" if len(n) == 1 else f"{n[0]}-{n[-1]}"
    seeds += " paired seed" if n == [1] else " paired seeds"
    if len(group[1]) == len(mine):  # names them: a table under way pairs only some methods
        return (f"{task_title(task)}: {name} is better than every method it was paired with "
                f"({', '.join(group[1])}; every 95% interval above 0, {seeds}).")
    parts = []
    if group[1]:
        parts.append(f"better than {', '.join(group[1])}")
    if group[-1]:
        parts.append(f"worse than {', '.join(group[-1])}")
    if group[0]:
        parts.append(f"not separable from {', '.join(group[0])} (the interval holds 0)")
    if single:
        parts.append(f"compared on one seed only with {', '.join(single)} (no interval)")
    return f"{task_title(task)}: {name} is {'; '.join(parts)} ({seeds})."


def paired_markdown(rows: list[dict], method: str = "diffusebot") -> str:
    """The paired differences as a markdown table, then the verdict of every task."""
    diffs = paired_differences(rows, method)
    if not diffs:
        return f"No task has a seed done by {method_name(method)} and another method.\n"

    def g(x: float | None) -> str:
        return "–" if x is None else f"{x:.3g}"

    lines = [f"| task | {method_name(method)} − | seeds | mean difference | 95% interval | |",
             "| --- | --- | ---: | ---: | --- | --- |"]
    for d in diffs:
        mark = {1: "better", -1: "worse", 0: "–" if d["lo"] is None else "holds 0"}[d["sign"]]
        ci = "–" if d["lo"] is None else f"[{g(d['lo'])}, {g(d['hi'])}]"
        lines.append(f"| {task_title(d['task'])} | {method_name(d['other'])} | {d['n']} | "
                     f"{g(d['mean'])} | {ci} | {mark} |")
    tasks = ordered({d["task"] for d in diffs}, TASKS)
    return "\n".join(lines) + "\n\n" + "\n".join(f"- {verdict(diffs, t)}" for t in tasks) + "\n"
