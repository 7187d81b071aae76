"""Honest validation of the combined stiction verdict and of the S/J estimates.

Data
----
* every labelled real recording in ``valve_gym/data/stictiongpt_plant_loops`` (49 records, 24 tags);
* textbook closed loops of :mod:`valve_gym.diagnosis.stiction.loops` (an independently written
  simulator): FOPTD, integrating and Torricelli-tank processes, Choudhury, Kano and force-balance
  friction with S 0.5-10 % of stroke, healthy valves with external oscillating loads or
  over-aggressive tuning, white or coloured noise, sample times 0.5-5 s.

Every record is diagnosed once (``diagnose(rec, plant, candidates=())``: base fit + friction
verdict + the model-free methods) and its feature vector cached.  Settings fixed before any
held-out score is read: L2 penalty 1, undecided band 0.5 +- 0.1, each real tag weighs as much as
3 simulated loops in training, sims split by seed parity.

Scores
------
* real loops, leave-one-loop-out **by tag**: for each tag the logistic model is fitted on all
  simulated loops and the *other* tags, then applied to the held-out tag's records.  Balanced
  accuracy per tag (majority of its records; undecided counts as a miss) and per record;
  confusion matrix.
* simulated loops, two-fold by seed parity (all real tags in training), and leave-one-friction-
  model-out (the sticky loops of one friction model never in training).
* S and J: on the sticky simulated loops called stiction, coverage of the true S and J by the 90 %
  intervals, median relative error, and how often the two size methods agree.

Usage::

    nice -n 10 python benchmarks/validate_stiction.py [--n-sim 160] [--jobs 2]
        [--cache stiction_features.json] [--write-model] [--docs docs/diagnosis.md]
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import time
from collections import defaultdict

import numpy as np

from valve_gym._io import write_atomic
from valve_gym.diagnosis import data_path, diagnose, load_recording
from valve_gym.diagnosis.model import process_pool
from valve_gym.diagnosis.select import SelectionRule
from valve_gym.diagnosis.stiction import (
    FEATURES,
    SizeEstimate,
    fit_logistic,
    model_free_evidence,
    oscillation,
)
from valve_gym.diagnosis.stiction.combine import combine_sizes, features, verdict_of
from valve_gym.diagnosis.stiction.hammerstein import hammerstein_evidence
from valve_gym.diagnosis.stiction.loops import random_spec, simulate_loop

L2 = 1.0
REAL_TAG_WEIGHT = 3.0
PLANT_OF = {"foptd": "first_order", "integrating": "integrating", "tank": "tank"}
MARK_BEGIN = "<!-- validate_stiction:begin -->"
MARK_END = "<!-- validate_stiction:end -->"


def _real_items():
    folder = data_path("stictiongpt_plant_loops")
    rows = list(csv.DictReader(open(os.path.join(folder, "index.csv"), encoding="utf-8")))
    return [{"kind": "real", "path": os.path.join(folder, r["csv_file"]), "tag": r["tag"],
             "label": int(r["expert_label"] == "stiction"),
             "plant": "integrating" if "LIC" in r["csv_file"].upper() else "first_order",
             "name": os.path.basename(r["csv_file"])} for r in rows]


def _sim_items(n_sim):
    out = []
    for seed in range(n_sim):
        rng = np.random.default_rng(50_000 + seed)
        sticky = seed % 2 == 0 if seed % 4 != 3 else bool(rng.random() < 0.5)
        spec = random_spec(rng, sticky)
        out.append({"kind": "sim", "seed": seed, "tag": f"sim{seed}", "label": int(spec.sticky),
                    "plant": PLANT_OF[spec.process], "process": spec.process, "valve": spec.valve,
                    "S_true": spec.S, "J_true": spec.J, "spec": spec.__dict__,
                    "name": f"{spec.process}_{spec.valve}_{seed}"})
    return out


def _load(item):
    from valve_gym.diagnosis.stiction.loops import LoopSpec
    if item["kind"] == "real":
        return load_recording(item["path"], op_range=(0, 100))
    return simulate_loop(LoopSpec(**item["spec"]), seed=item["seed"], name=item["name"])


def _run_one(item):
    """The model-based part (slow): diagnose with the base model only; keep its verdict and sizes."""
    t0 = time.perf_counter()
    rec = _load(item)
    res = diagnose(rec, plant=item["plant"], candidates=(), jobs=1)
    s = res.stiction
    out = {k: v for k, v in item.items() if k != "spec"}
    out.update({"verdict": {k: s.get(k) for k in ("tested", "present", "delta_ic", "band", "band_needed")},
                "features": s["features"], "sizes": s["sizes"],
                "model_based_present": s["model_based_present"],
                "seconds": time.perf_counter() - t0, "n": len(rec)})
    out["verdict"]["present"] = s["model_based_present"]
    return out


def _hammerstein(r):
    """The model-based evidence of a cached record."""
    s_slip = next((s["S"] for s in r["sizes"] if s["method"] == "hammerstein" and s["S"] is not None),
                  float("nan"))
    if "verdict" not in r:                  # older cache: rebuild the verdict from its two features
        f = r["features"]
        need = _band_needed(r["_op"])
        r["verdict"] = {"tested": True, "present": r["model_based_present"],
                        "delta_ic": -2.0 * float(np.sinh(f["hammerstein"])),
                        "band": need * 10.0 ** float(f["hammerstein_band"]), "band_needed": need}
    return hammerstein_evidence(r["verdict"], s_slip)


def _band_needed(op, rule=SelectionRule()):
    """The band the model-only verdict asks for (as in ``diagnose``), fraction of stroke."""
    op_range = float(np.quantile(op, 0.98) - np.quantile(op, 0.02))
    return max(rule.min_band, min(rule.abs_band, rule.rel_band * op_range))


def refresh(data, items):
    """Model-free evidence, features and sizes of every record with the current code (fast)."""
    by_name = {it["name"]: it for it in items}
    for r in data:
        rec = _load(by_name[r["name"]])
        r["_op"] = rec.op
        ev = model_free_evidence(rec.op, rec.pv, float(rec.dt or 1.0), r["plant"], rec.sp) + [_hammerstein(r)]
        del r["_op"]
        r["features"] = dict(zip(FEATURES, map(float, features(ev, r["plant"]))))
        ell = next(e for e in ev if e.method == "ellipse")
        nan = float("nan")
        sizes = [SizeEstimate("hammerstein", *[nan if s[k] is None else float(s[k]) for k in SizeEstimate._fields[1:]])
                 for s in r["sizes"] if s["method"] == "hammerstein"]
        if ell.applicable:
            sizes.append(SizeEstimate("ellipse", ell.details["S_app"], ell.details["S_lo"],
                                      ell.details["S_hi"], nan, nan, nan))
        size, agree = combine_sizes(sizes)
        r.update({"S": size.S, "J": size.J, "S_interval": [size.S_lo, size.S_hi],
                  "J_interval": [size.J_lo, size.J_hi], "sizes_agree": agree,
                  "size_methods": [s._asdict() for s in sizes],
                  "oscillates": bool(oscillation(rec.pv).present or oscillation(rec.op).present)})
    return data


def collect(n_sim, jobs, cache):
    """Diagnose every record once (cached in ``cache``); returns the list of feature records."""
    done = {}
    if cache and os.path.exists(cache):
        with open(cache, encoding="utf-8") as f:
            done = {d["name"]: d for d in json.load(f)}
    items = _real_items() + _sim_items(n_sim)
    todo = [it for it in items if it["name"] not in done]
    t0 = time.perf_counter()
    if todo:
        with process_pool(jobs) as ex:
            for i, r in enumerate(ex.map(_run_one, todo, chunksize=2)):
                done[r["name"]] = r
                if (i + 1) % 10 == 0 or i + 1 == len(todo):
                    print(f"[{i + 1}/{len(todo)}] diagnosed ({time.perf_counter() - t0:.0f} s)",
                          file=sys.stderr, flush=True)
                    if cache:
                        _save(cache, list(done.values()))
    return refresh([done[it["name"]] for it in items], items)


def _save(path, data):
    write_atomic(path, lambda f: f.write(json.dumps(data).encode()))


def _xyw(recs):
    X = np.array([[r["features"][k] or 0.0 for k in FEATURES] for r in recs])
    y = np.array([r["label"] for r in recs], float)
    n_tag = defaultdict(int)
    for r in recs:
        n_tag[r["tag"]] += 1
    w = np.array([REAL_TAG_WEIGHT / n_tag[r["tag"]] if r["kind"] == "real" else 1.0 for r in recs])
    return X, y, w


def _predict(train, test):
    X, y, w = _xyw(train)
    m = fit_logistic(X, y, l2=L2, weights=w)
    Xt, _, _ = _xyw(test)
    return m.probability(Xt)


def _scores(labels, verdicts):
    """TPR, TNR, balanced accuracy; 'undecided' counts as a miss."""
    labels = np.asarray(labels, bool)
    hit = np.array([(v == "stiction") if lab else (v == "no stiction") for lab, v in zip(labels, verdicts)])
    tpr = hit[labels].mean() if labels.any() else float("nan")
    tnr = hit[~labels].mean() if (~labels).any() else float("nan")
    return float(tpr), float(tnr), float(0.5 * (tpr + tnr))


def _confusion(labels, verdicts):
    c = {(lab, v): 0 for lab in (1, 0) for v in ("stiction", "undecided", "no stiction")}
    for lab, v in zip(labels, verdicts):
        c[(int(lab), v)] += 1
    return c


def _observable(r):
    """A simulated loop whose friction shows: healthy, or sticky with a regular cycle in OP or PV."""
    return r["label"] == 0 or r["oscillates"]


def lolo_real(data):
    """Leave-one-tag-out on the real loops (observable sims and the other tags in training)."""
    real = [r for r in data if r["kind"] == "real"]
    sims = [r for r in data if r["kind"] == "sim" and _observable(r)]
    for tag in sorted({r["tag"] for r in real}):
        test = [r for r in real if r["tag"] == tag]
        train = sims + [r for r in real if r["tag"] != tag]
        for r, p in zip(test, _predict(train, test)):
            r["p_heldout"] = float(p)
            r["verdict_heldout"] = verdict_of(float(p))
    per_tag = defaultdict(list)
    for r in real:
        per_tag[r["tag"]].append(r)
    tag_lab, tag_v = [], []
    for tag, rs in sorted(per_tag.items()):
        votes = [r["verdict_heldout"] for r in rs]
        best = max(("stiction", "no stiction", "undecided"), key=lambda v: (votes.count(v), v == "undecided"))
        tag_lab.append(rs[0]["label"])
        tag_v.append(best)
    return real, (tag_lab, tag_v), per_tag


def heldout_sims(data):
    """Two-fold by seed parity, real loops always in training; training uses observable sims only."""
    real = [r for r in data if r["kind"] == "real"]
    sims = [r for r in data if r["kind"] == "sim"]
    for par in (0, 1):
        test = [r for r in sims if r["seed"] % 2 == par]
        train = real + [r for r in sims if r["seed"] % 2 != par and _observable(r)]
        for r, p in zip(test, _predict(train, test)):
            r["p_heldout"] = float(p)
            r["verdict_heldout"] = verdict_of(float(p))
    out = {}
    obs = [r for r in sims if _observable(r)]
    for valve in ("choudhury", "kano", "force_balance"):
        test = [r for r in obs if r["valve"] == valve or r["label"] == 0 and r["seed"] % 2 == 1]
        train = real + [r for r in obs if r["valve"] != valve and not (r["label"] == 0 and r["seed"] % 2 == 1)]
        ps = _predict(train, test)
        out[valve] = _scores([r["label"] for r in test], [verdict_of(float(p)) for p in ps])
    return sims, out


def size_scores(sims):
    """Coverage and error of the S/J estimates on sticky simulated (cycling) loops called stiction."""
    rows = [r for r in sims if r["label"] == 1 and r["verdict_heldout"] == "stiction" and np.isfinite(r["S"])]
    if not rows:
        return {"n": 0}

    def cover(key, truth):
        ok = [r[key][0] <= r[truth] <= r[key][1] for r in rows if np.isfinite(r[key][0])]
        return float(np.mean(ok)) if ok else float("nan"), len(ok)

    s_cov, ns = cover("S_interval", "S_true")
    j_cov, nj = cover("J_interval", "J_true")
    s_err = [abs(r["S"] - r["S_true"]) / r["S_true"] for r in rows]
    j_err = [abs(r["J"] - r["J_true"]) / r["J_true"] for r in rows if np.isfinite(r["J"])]
    agree = [r["sizes_agree"] for r in rows if r["sizes_agree"] is not None]
    by_method = {}
    for m in ("ellipse", "hammerstein"):
        ests = [(s, r) for r in rows for s in r["size_methods"] if s["method"] == m]
        if ests:
            by_method[m] = {"n": len(ests),
                            "cover": float(np.mean([s["S_lo"] <= r["S_true"] <= s["S_hi"] for s, r in ests])),
                            "median_rel_err": float(np.median([abs(s["S"] - r["S_true"]) / r["S_true"]
                                                               for s, r in ests]))}
    return {"n": len(rows), "S_cover": s_cov, "n_S": ns, "J_cover": j_cov, "n_J": nj,
            "S_median_rel_err": float(np.median(s_err)),
            "J_median_rel_err": float(np.median(j_err)) if j_err else float("nan"),
            "agree": float(np.mean(agree)) if agree else float("nan"), "n_agree": len(agree),
            "by_method": by_method}


def _conf_table(title, labels, verdicts):
    c = _confusion(labels, verdicts)
    tpr, tnr, bal = _scores(labels, verdicts)
    lines = [f"{title}: TPR {tpr:.2f}, TNR {tnr:.2f}, **balanced accuracy {bal:.2f}** "
             f"(undecided counts as a miss)\n",
             "| label \\ verdict | stiction | undecided | no stiction |", "|---|---|---|---|"]
    for lab, name in ((1, "stiction"), (0, "no stiction")):
        lines.append(f"| {name} | {c[(lab, 'stiction')]} | {c[(lab, 'undecided')]} | "
                     f"{c[(lab, 'no stiction')]} |")
    return "\n".join(lines) + "\n"


def report(data, n_sim, seconds):
    """Markdown report of all scores."""
    real, (tag_lab, tag_v), per_tag = lolo_real(data)
    sims_all, by_valve = heldout_sims(data)
    sims = [r for r in sims_all if _observable(r)]
    hidden = [r for r in sims_all if not _observable(r)]
    out = [f"Command: `nice -n 10 python benchmarks/validate_stiction.py --n-sim {n_sim} --jobs 2` "
           f"({seconds:.0f} s for the diagnoses on the shared 2-core machine).\n"]
    out.append(_conf_table(f"Real loops, leave-one-tag-out, per tag ({len(tag_lab)} tags, majority "
                           "of the tag's records)", tag_lab, tag_v))
    out.append(_conf_table(f"Real loops, leave-one-tag-out, per record ({len(real)} records)",
                           [r["label"] for r in real], [r["verdict_heldout"] for r in real]))
    old = _scores([r["label"] for r in real],
                  ["stiction" if r["model_based_present"] else "no stiction" for r in real])
    out.append(f"Reference in the same run, the model-only verdict of the previous release on the same "
               f"records: TPR {old[0]:.2f}, TNR {old[1]:.2f}, balanced {old[2]:.2f} per record.\n")
    out.append(_conf_table(f"Simulated textbook loops, two-fold by seed ({len(sims)} loops: every healthy "
                           "loop and every sticky loop that cycles)",
                           [r["label"] for r in sims], [r["verdict_heldout"] for r in sims]))
    k = sum(r["verdict_heldout"] == "stiction" for r in hidden)
    out.append(f"Sticky loops that do not cycle (no regular oscillation of PV or OP; left out of training "
               f"and of the score above): {k} of {len(hidden)} called stiction.\n")
    rows = ["| process | friction | loops | right |", "|---|---|---|---|"]
    for key in sorted({(r["process"], r["valve"]) for r in sims}):
        sub = [r for r in sims if (r["process"], r["valve"]) == key]
        ok = sum(r["verdict_heldout"] == ("stiction" if r["label"] else "no stiction") for r in sub)
        rows.append(f"| {key[0]} | {key[1]} | {len(sub)} | {ok} |")
    out.append("\n".join(rows) + "\n")
    rows = ["| friction model held out of training | TPR | TNR | balanced |", "|---|---|---|---|"]
    for v, (a, b, c) in by_valve.items():
        rows.append(f"| {v} | {a:.2f} | {b:.2f} | {c:.2f} |")
    out.append("\n".join(rows) + "\n")
    out.append(_size_text(size_scores(sims)))
    return "\n".join(out)


def _size_text(sz):
    if not sz.get("n"):
        return "No sticky simulated loop was called stiction: no size estimate to score.\n"
    t = (f"Stiction size on the {sz['n']} sticky simulated loops called stiction: combined S within its "
         f"90 % interval in {sz['S_cover']:.0%} ({sz['n_S']}), J in {sz['J_cover']:.0%} ({sz['n_J']}); "
         f"median relative error S {sz['S_median_rel_err']:.0%}, J {sz['J_median_rel_err']:.0%}; the two "
         f"S methods' intervals overlap in {sz['agree']:.0%} ({sz['n_agree']}).\n\n")
    t += "| S method | loops | true S inside its 90 % interval | median relative error |\n|---|---|---|---|\n"
    for m, d in sz["by_method"].items():
        t += f"| {m} | {d['n']} | {d['cover']:.0%} | {d['median_rel_err']:.0%} |\n"
    return t


def write_model(data, path):
    """Fit the logistic model on every record and write it as the package's default."""
    X, y, w = _xyw([r for r in data if r["kind"] == "real" or _observable(r)])
    m = fit_logistic(X, y, l2=L2, weights=w)
    d = m.to_dict()
    txt = ('"""Weights of the stiction logistic model (written by '
           '``benchmarks/validate_stiction.py --write-model``)."""\n'
           f"MODEL = {json.dumps(d, indent=1)}\n")
    write_atomic(path, lambda f: f.write(txt.encode()))
    return d


def _docs(path, text):
    with open(path, encoding="utf-8") as f:
        doc = f.read()
    block = f"{MARK_BEGIN}\n{text}\n{MARK_END}"
    if MARK_BEGIN in doc:
        a, b = doc.index(MARK_BEGIN), doc.index(MARK_END) + len(MARK_END)
        doc = doc[:a] + block + doc[b:]
    else:
        doc += "\n" + block + "\n"
    write_atomic(path, lambda f: f.write(doc.encode()))


def main(argv=None):
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--n-sim", type=int, default=160)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--cache", default="stiction_features.json")
    ap.add_argument("--write-model", action="store_true",
                    help="fit on every record and write valve_gym/diagnosis/stiction/_weights.py")
    ap.add_argument("--docs", default=None, help="markdown file to put the report in (between markers)")
    a = ap.parse_args(argv)
    if a.n_sim < 8:
        raise SystemExit("--n-sim must be at least 8")
    t0 = time.perf_counter()
    data = collect(a.n_sim, a.jobs, a.cache)
    text = report(data, a.n_sim, time.perf_counter() - t0)
    print(text)
    if a.write_model:
        import valve_gym.diagnosis.stiction as pkg
        d = write_model(data, os.path.join(os.path.dirname(pkg.__file__), "_weights.py"))
        print("model written:", json.dumps(d))
    if a.docs:
        _docs(a.docs, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
