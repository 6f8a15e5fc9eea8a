"""Collects the outputs of bench/run.sh into bench/results.json and writes docs/results.md.

    /usr/bin/python3 bench/report.py --work /tmp/handdb-bench --handdb build-bench/cli/handdb \\
        --results bench/results.json --markdown docs/results.md --images docs/images/results

Reads WORK/out/<step>.txt|.err|.time (run.sh) and WORK/out/eval_*.json (handdb evaluate --json),
copies the evaluation plots into the images directory, and states the machine the numbers were
measured on. Steps that did not run are reported as such, never invented.
"""

import argparse
import datetime
import glob
import json
import os
import platform
import re
import shutil
import subprocess

EVALUATIONS = [
    ("paper_clean", "paper database, clean label renders"),
    ("paper_photo", "paper database, photos (plain background)"),
    ("paper_clutter", "paper database, photos (cluttered background)"),
    ("pca_large_clean", "pca-large database, clean label renders"),
    ("pca_large_photo", "pca-large database, photos (plain background)"),
]
PLOTS = ["rank_histogram.png", "rank_histogram_same_shape.png", "keypoint_error_cdf.png",
         "successes.png", "failures.png"]


def sh(cmd):
    try:
        return subprocess.run(cmd, shell=True, capture_output=True, text=True, timeout=60).stdout.strip()
    except Exception:  # noqa: BLE001 - machine facts are best effort
        return ""


def machine():
    cpu = ""
    for line in sh("lscpu").splitlines():
        if line.startswith("Model name:"):
            cpu = line.split(":", 1)[1].strip()
    mem_kb = 0
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemTotal:"):
                    mem_kb = int(line.split()[1])
    except OSError:
        pass
    os_name = ""
    try:
        with open("/etc/os-release") as f:
            for line in f:
                if line.startswith("PRETTY_NAME="):
                    os_name = line.split("=", 1)[1].strip().strip('"')
    except OSError:
        pass
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "memory_gib": round(mem_kb / 1024 / 1024, 1),
        "os": os_name,
        "kernel": platform.release(),
        "blender": sh("blender --version 2>/dev/null | head -n 1"),
        "compiler": sh("c++ --version | head -n 1"),
        "load_average": list(os.getloadavg()),
        "git_revision": sh("git rev-parse --short HEAD"),
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
    }


def read(path):
    try:
        with open(path) as f:
            return f.read()
    except OSError:
        return None


def step(out, name):
    t = read(os.path.join(out, name + ".time"))
    if t is None:
        return None
    info = json.loads(t)
    info["stdout"] = read(os.path.join(out, name + ".txt")) or ""
    info["stderr_tail"] = "\n".join((read(os.path.join(out, name + ".err")) or "").splitlines()[-5:])
    return info


def json_or_none(text):
    try:
        return json.loads(text)
    except (TypeError, ValueError):
        return None


def pct(x):
    if x is None:
        return "–"
    if 0 < x < 0.01:
        return f"{100.0 * x:.3f}%"
    return f"{100.0 * x:.1f}%"


def num(x, fmt="{:.3f}"):
    return "–" if x is None else fmt.format(x)


def success_rate(report, criterion, n):
    for cell in report["success"]:
        if cell["criterion"] == criterion and cell["n"] == n:
            return cell["rate"]
    return None


def table_row(report, criterion):
    for t in report["rank_tables"]:
        if t["criterion"] == criterion:
            return t
    return None


QUERY_SET_LINE = re.compile(
    r"^  (\S+)\s+(either|right)\s+median\s+([0-9.]+) ms\s+p90\s+([0-9.]+) ms\s+max\s+([0-9.]+) ms\s+"
    r"([0-9.]+|nan)x perturbed\s+refined median\s+([0-9.]+)% max\s+([0-9.]+)%\s+"
    r"view kd-trees median ([0-9.]+) max ([0-9.]+)"
    r"(?:\s+CPU median ([0-9.]+) ms \(([0-9.]+|nan)x perturbed\))?", re.M)
QUERY_SET_BRUTE = re.compile(r"^  (\S+)\s+brute force on the first (\d+) of (\d+) queries.*: (\S+)", re.M)
QUERY_SET_TITLES = {"photos": "real photos", "testset-photo": "test-set photo-like renders",
                    "testset-clean": "test-set clean label renders", "perturbed": "perturbed database views"}


def query_sets(text):
    """The per-set lines of query_bench's query sets (issue 15): {set: {hand: numbers}, ...}."""
    sets = {}
    for m in QUERY_SET_LINE.finditer(text or ""):
        sets.setdefault(m.group(1), {})[m.group(2)] = {
            "median_ms": float(m.group(3)), "p90_ms": float(m.group(4)), "max_ms": float(m.group(5)),
            "ratio_to_perturbed_median": float(m.group(6)),
            "refined_share_median": float(m.group(7)) / 100, "refined_share_max": float(m.group(8)) / 100,
            "view_kdtrees_median": float(m.group(9)), "view_kdtrees_max": float(m.group(10)),
            "cpu_median_ms": float(m.group(11)) if m.group(11) else None,
            "cpu_ratio_to_perturbed_median": float(m.group(12)) if m.group(12) else None}
    for m in QUERY_SET_BRUTE.finditer(text or ""):
        sets.setdefault(m.group(1), {})["brute_force"] = {
            "checked": int(m.group(2)), "queries": int(m.group(3)), "identical": m.group(4) == "identical"}
    return sets


def eval_summary(report):
    chance = {c["n"]: c["rate"] for c in report["chance"]["success"]}
    return {
        "database_virtual_views": report["database"]["virtual_views"],
        "test_views": report["testset"]["views"],
        "input": report["input"],
        "table1_main": table_row(report, "main")["counts"],
        "table1_same_shape": table_row(report, "same-shape")["counts"],
        "same_shape_views": table_row(report, "same-shape")["total"],
        "same_shape_none_in_database": table_row(report, "same-shape").get("no_correct_in_database"),
        "success_main": {n: success_rate(report, "main", n) for n in (1, 10, 100)},
        "success_same_shape": {n: success_rate(report, "same-shape", n) for n in (1, 10, 100)},
        "chance_main": chance,
        "keypoint_error_top1_median": report["keypoint_error"]["top1"]["median"],
        "keypoint_error_top1_mean": report["keypoint_error"]["top1"]["mean"],
        "keypoint_error_best10_median": report["keypoint_error"]["best_of_top10"]["median"],
        "keypoint_error_best10_mean": report["keypoint_error"]["best_of_top10"]["mean"],
        "queries_per_second": report["timing"]["queries_per_second"],
        "end_to_end_queries_per_second": report["timing"]["end_to_end_queries_per_second"],
        "failed_inputs": report["failed_inputs"],
        "threads": report["search"]["threads"],
    }


def md_table1(report):
    bins = report["rank_tables"][0]["bins"]
    lines = ["| criterion | " + " | ".join(bins) + " | views | of them with no correct view in the database |",
             "|---|" + "---:|" * (len(bins) + 2)]
    for t in report["rank_tables"]:
        if t["criterion"] not in ("main", "same-shape"):
            continue
        c = next(c for c in report["criteria"] if c["name"] == t["criterion"])
        rule = (f"{'same shape (basic-shape views)' if c['same_shape'] else 'joints ≤ %g° %s' % (c['max_joint_distance_deg'], c['joint_distance'].upper())}"
                f", dir ≤ {c['max_direction_deg']:g}°, roll ≤ {c['max_roll_deg']:g}°")
        name = f"{t['criterion']}: {rule}"
        none = t.get("no_correct_in_database", "–")
        lines.append(f"| {name} | " + " | ".join(str(c) for c in t["counts"]) + f" | {t['total']} | {none} |")
    return "\n".join(lines)


def md_success(report):
    ns = sorted({c["n"] for c in report["success"]})
    lines = ["| criterion | " + " | ".join(f"n = {n}" for n in ns) + " |", "|---|" + "---:|" * len(ns)]
    for crit in [c["name"] for c in report["criteria"]]:
        label = {"main": "main (d = 15°)", "same-shape": "same shape"}.get(crit, crit)
        lines.append(f"| {label} | " + " | ".join(pct(success_rate(report, crit, n)) for n in ns) + " |")
    if report["chance"]["computed"]:
        chance = {c["n"]: c["rate"] for c in report["chance"]["success"]}
        lines.append("| chance (random ordering, main) | " + " | ".join(pct(chance.get(n)) for n in ns) + " |")
    return "\n".join(lines)


def code_block(text, limit=60):
    lines = (text or "").rstrip().splitlines()
    if len(lines) > limit:
        lines = lines[:limit] + [f"... ({len(lines) - limit} more lines in bench/results.json)"]
    return "```\n" + "\n".join(lines) + "\n```"


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--work", required=True)
    p.add_argument("--handdb", default="")
    p.add_argument("--results", required=True)
    p.add_argument("--markdown", required=True)
    p.add_argument("--images", required=True)
    args = p.parse_args()
    out = os.path.join(args.work, "out")

    results = {"machine": machine(), "steps": {}, "evaluations": {}}
    for path in sorted(glob.glob(os.path.join(out, "*.time"))):
        name = os.path.basename(path)[:-5]
        results["steps"][name] = step(out, name)

    render = json_or_none((results["steps"].get("render") or {}).get("stdout"))
    results["render"] = render
    gen = json_or_none((results["steps"].get("generate_paper") or {}).get("stdout"))
    results["generate_paper"] = gen

    reports = {}
    os.makedirs(args.images, exist_ok=True)
    for name, _ in EVALUATIONS:
        doc = json_or_none(read(os.path.join(out, f"eval_{name}.json")))
        if doc is None:
            continue
        reports[name] = doc
        results["evaluations"][name] = eval_summary(doc)
        for plot in PLOTS:
            src = os.path.join(args.work, "plots", name, plot)
            if os.path.exists(src):
                shutil.copyfile(src, os.path.join(args.images, f"{name}_{plot}"))

    results["query_sets"] = {
        step_name: query_sets((results["steps"].get(step_name) or {}).get("stdout"))
        for step_name in ("query", "query_pca_large")}

    pca = results["steps"].get("generate_pca_large")
    results["pca_large"] = {"run": pca is not None and pca["exit_code"] == 0}

    with open(args.results + ".tmp", "w") as f:
        json.dump(results, f, indent=1)
        f.write("\n")
    os.replace(args.results + ".tmp", args.results)

    # ---- docs/results.md ----
    m = results["machine"]
    img_rel = os.path.relpath(args.images, os.path.dirname(os.path.abspath(args.markdown)))
    md = ["# handdb results", "",
          "Measured by `bench/run.sh` (every benchmark in one run; raw outputs in `bench/results.json`).",
          "Accuracy follows docs/evaluation.md; speed ratios are against baselines measured in the same run.", "",
          "## Machine", "",
          f"- CPU: {m['cpu']}, {m['cores']} cores (shared with other work while this ran: load average "
          f"{m['load_average'][0]:.1f} / {m['load_average'][1]:.1f} / {m['load_average'][2]:.1f} at report time)",
          f"- Memory: {m['memory_gib']} GiB; OS: {m['os']} (kernel {m['kernel']})",
          f"- {m['blender']}; {m['compiler']}",
          f"- handdb revision {m['git_revision']}, {m['date']}", ""]

    # Headline.
    md += ["## Summary", ""]
    rows = ["| measurement | value | baseline in the same run | ratio |", "|---|---:|---:|---:|"]
    if render:
        rate = render.get("renders_per_s")
        bare = render.get("bare_blender_start_s")
        if rate:
            rows.append(f"| Blender label renders/s ({render.get('jobs', '?')} processes, wall) | {rate:.1f} | "
                        f"one bare Blender start {num(bare, '{:.2f}')} s | "
                        f"{'%.0f renders in the time of one start' % (rate * bare) if bare else '–'} |")
            if render.get("cpu_bound_renders_per_s"):
                rows.append(f"| Blender label renders/s if the cores were free (CPU time) | "
                            f"{render['cpu_bound_renders_per_s']:.1f} | target 15/s | "
                            f"{render['cpu_bound_renders_per_s'] / 15.0:.2f}x |")
    # Headlines of the C++ benchmarks, read from their text output (a row is left out if the
    # output's wording changed; the full output is in its section below).
    def grab(step_name, pattern):
        text = (results["steps"].get(step_name) or {}).get("stdout") or ""
        m_ = re.search(pattern, text)
        return m_.groups() if m_ else None
    g = grab("format", r"scan / raw read = ([0-9.]+) by cpu time")
    if g:
        rows.append(f"| shard sequential scan, share of raw `read()` speed (CPU time) | {g[0]} | raw read() = 1 | {g[0]} |")
    g = grab("convert", r"convert, 2 threads: [0-9.]+ s, ([0-9.]+) canonical views/s")
    g1 = grab("convert", r"convert, 1 thread : [0-9.]+ s, ([0-9.]+) canonical views/s")
    if g and g1:
        rows.append(f"| convert, canonical views/s (2 threads) | {g[0]} | 1 thread {g1[0]} | "
                    f"{float(g[0]) / float(g1[0]):.2f}x |")
    g = grab("query", r"\(a\) pruned exact\s+median\s+([0-9.]+) ms")
    gb = grab("query", r"\(b\) brute force\s+median\s+([0-9.]+) ms")
    if g and gb:
        rows.append(f"| query latency, top 10, paper database (pruned exact search) | {g[0]} ms | "
                    f"brute force {gb[0]} ms | {float(gb[0]) / float(g[0]):.0f}x faster |")
    for step_name, db_title in [("query", "paper"), ("query_pca_large", "pca-large")]:
        g = grab(step_name, r"\(a\) pruned exact\s+median\s+([0-9.]+) ms")
        c = grab(step_name, r"\(a\) CPU / \d+ threads = ([0-9.]+) ms")
        mem = grab(step_name, r"DB on disk ([0-9.]+) MB; \(peak during \(a\) - RSS before\) / DB = ([0-9.]+)")
        if g and step_name == "query_pca_large":
            rows.append(f"| query latency, top 10, pca-large database (pruned exact search) | {g[0]} ms "
                        f"(CPU {c[0] if c else '?'} ms per thread) | – | – |")
        if mem:
            rows.append(f"| peak memory during queries, {db_title} database (RSS growth / DB size) | "
                        f"{mem[1]}x | DB {mem[0]} MiB on disk | target <= 1.5x |")
    for step_name, db_title in [("query", "paper"), ("query_pca_large", "pca-large")]:
        sets = results["query_sets"].get(step_name) or {}
        for key, set_title in QUERY_SET_TITLES.items():
            e = (sets.get(key) or {}).get("either")
            if not e or key == "perturbed":  # the baseline column
                continue
            ref = (sets.get("perturbed") or {}).get("either")
            brute = (sets.get(key) or {}).get("brute_force")
            checked = (f"; brute force identical on {brute['checked']}" if brute and brute["identical"]
                       else f"; brute force DIFFERENT on {brute['checked']} checked" if brute else "")
            rows.append(f"| query latency, {db_title} database, {set_title} (`handdb query` default "
                        f"--hand either): median / p90 / max | {e['median_ms']:.0f} / {e['p90_ms']:.0f} / "
                        f"{e['max_ms']:.0f} ms (refined {pct(e['refined_share_median'])}{checked}) | "
                        f"perturbed views median {num(ref and ref['median_ms'], '{:.0f}')} ms | "
                        f"{e['ratio_to_perturbed_median']:.2f}x"
                        + (f" (CPU {e['cpu_ratio_to_perturbed_median']:.2f}x)"
                           if e.get("cpu_ratio_to_perturbed_median") is not None else "") + " |")
    for name, title in EVALUATIONS:
        s = results["evaluations"].get(name)
        if not s:
            continue
        ss1 = s["success_same_shape"][1]
        ss10 = s["success_same_shape"][10]
        if ss1 is not None and s["same_shape_none_in_database"] == s["same_shape_views"]:
            rows.append(f"| {title}: same-shape success | not applicable: none of the "
                        f"{s['same_shape_views']} basic-shape test shapes is in this database | – | – |")
        elif ss1 is not None:
            rows.append(f"| {title}: same-shape success@1 / @10 (paper's rule, {s['same_shape_views']} "
                        f"basic-shape views) | {pct(ss1)} / {pct(ss10)} | – | – |")
        s1 = s["success_main"][1]
        c1 = s["chance_main"].get(1)
        rows.append(f"| {title}: success@1 (d = 15°) | {pct(s1)} | chance {pct(c1)} | "
                    f"{'%.0fx' % (s1 / c1) if s1 and c1 else '–'} |")
        s100 = s["success_main"][100]
        c100 = s["chance_main"].get(100)
        rows.append(f"| {title}: success@100 (d = 15°) | {pct(s100)} | chance {pct(c100)} | "
                    f"{'%.1fx' % (s100 / c100) if s100 and c100 else '–'} |")
        rows.append(f"| {title}: queries/s (top 100, {s['threads']} threads) | "
                    f"{s['queries_per_second']:.2f} | – | – |")
    md += rows + [""]

    def section(title, step_name, intro):
        st = results["steps"].get(step_name)
        md.extend([f"## {title}", "", intro, ""])
        if st is None:
            md.extend(["Not run.", ""])
            return
        md.append(f"Wall time {st['seconds']:.1f} s, exit code {st['exit_code']}: `{st['command']}`")
        md.extend(["", code_block(st["stdout"] or st["stderr_tail"]), ""])

    section("Shard format", "format",
            "`bench/format_bench`: write / sequential scan / validate of synthetic shards, against `read()` "
            "of the same bytes (the floor).")
    section("Rendering", "render",
            "`bench/render_bench.py`: label renders per second of `blender_scripts/render.py`, against one "
            "bare Blender start.")
    section("Database generation (paper config)", "generate_paper",
            "`handdb generate configs/paper.json`: 26 basic shapes x 86 directions (2,236 renders) x 48 "
            "rolls = 107,328 virtual views. (A rerun that finds the database complete only validates it.)")
    section("Conversion", "convert",
            "`bench/convert_bench` on the paper renders: views/s with 1 and 2 threads.")
    section("Query", "query",
            "`bench/query_bench` on the paper database: pruned exact search vs brute force vs a naive "
            "PCL baseline vs the read floor; then the query sets users send (issue 15): real photos "
            "(`--photos`), the test set's photo-like and clean label renders (`--testset`), and the "
            "perturbed views of (a), each searched with `handdb query`'s default `--hand either` and with "
            "`--hand right` (latency median / p90 / max, share of the searched pairs refined, view "
            "kd-trees), brute force on the first `--brute-queries` of each set.")
    md += [QUERY_SETS_HOWTO, ""]
    section("Test sets", "testset_paper",
            "`handdb testset configs/testset-paper.json` (200 views: 100 basic shapes, 100 PCA samples; "
            "uniform directions and rolls) with plain photos; the cluttered set renders the same views.")

    md += ["## Evaluation", "",
           "`handdb evaluate` (docs/evaluation.md). Table 1 counts test views by the rank of their "
           "highest-ranking correct match; the main criterion is joint distance ≤ 15° RMS, view "
           "direction ≤ 30°, roll ≤ 30°; *same shape* is the paper's rule on the basic-shape views. "
           "The chance row is what a random ordering of the database would reach (the in-run baseline). "
           "Keypoint error: mean root-relative 3D keypoint distance / hand size.", ""]
    for name, title in EVALUATIONS:
        rep = reports.get(name)
        if rep is None:
            continue
        s = results["evaluations"][name]
        md += [f"### {title}", "",
               f"{rep['testset']['views']} test views against {rep['database']['virtual_views']:,} virtual "
               f"views; {rep['failed_inputs']} views without a usable query; "
               f"{rep['timing']['deep_searches']} deeper searches for exact ranks.", "",
               md_table1(rep), "", md_success(rep), "",
               f"Keypoint error (hand sizes): top-1 median {num(s['keypoint_error_top1_median'])}, mean "
               f"{num(s['keypoint_error_top1_mean'])}; best of top 10 median "
               f"{num(s['keypoint_error_best10_median'])}, mean {num(s['keypoint_error_best10_mean'])}. "
               f"Speed: {s['queries_per_second']:.2f} queries/s (search), "
               f"{s['end_to_end_queries_per_second']:.2f} end to end, {s['threads']} threads.", ""]
        for plot, caption in [("rank_histogram.png", "Table 1"), ("keypoint_error_cdf.png", "keypoint error CDF"),
                              ("successes.png", "successes"), ("failures.png", "failures")]:
            if os.path.exists(os.path.join(args.images, f"{name}_{plot}")):
                md.append(f"![{title}: {caption}]({img_rel}/{name}_{plot})")
        md.append("")

    md += ["## The pca-large database", ""]
    pca_gen = results["steps"].get("generate_pca_large")
    if pca_gen is not None:
        md += ["`configs/pca-large.json`: 256 PCA shapes (8 components, Sobol) x 86 directions x 48 rolls = "
               "1,056,768 virtual views; evaluated above when the evaluation step ran.", "",
               f"`{pca_gen['command']}` (wall {pca_gen['seconds']:.1f} s, exit {pca_gen['exit_code']}):", "",
               code_block(pca_gen["stdout"] or pca_gen["stderr_tail"])]
    else:
        md += [PCA_LARGE_NOTE]
    section("Query on the pca-large database", "query_pca_large",
            "`bench/query_bench` on pca-large (1,056,768 virtual views): pruned exact search, the naive "
            "baseline (scaled from 0.1% of the views) and the read floor; brute force is left out "
            "(minutes per query). The query sets as on the paper database, 8 queries each.")
    section("Indexed search (issue 12)", "index_bench_paper",
            "`bench/index_bench` on the paper database after `handdb index`: indexed search (the index's "
            "candidates, then the exact refine) against exact search on the same query sets, with "
            "recall@1 / @10 against exact search and the candidates refined (docs/index.md).")
    section("Point and field compression (issue 12)", "point_codec_paper",
            "`bench/point_codec_bench` on the paper database (index built): each view's points chain-coded "
            "on the render's pixel lattice (format/point_codec.h) and its coarse field predictively coded "
            "(format/field_codec.h), both checked lossless against the shards, decode time per view on one "
            "thread, and the bytes per canonical and per virtual view they give (docs/format.md "
            "section 10; coded shards carry them since session 18, `handdb generate --coded`).")
    for size in ("10m", "50m"):
        if results["steps"].get(f"index_bench_synth_{size}") is not None:
            section(f"Indexed search at {size[:-1]}M virtual views (synthetic)", f"index_bench_synth_{size}",
                    f"`bench/synth_db` near-copies of a real database's views, {size[:-1]}M virtual views, "
                    "indexed and measured like the paper database (`HANDDB_BENCH_SCALE=1`).")
    if results["steps"].get("index_bench_synth_10m_coded") is not None:
        section("Indexed search at 10M virtual views, coded shards (synthetic)", "index_bench_synth_10m_coded",
                "`bench/synth_db --coded`: the 10M synthetic database with coded shards (format v1.2, "
                "docs/format.md section 10), its points snapped to the render lattice; indexed and measured "
                "like the plain one.")
    if results["steps"].get("plot_scaling") is not None:
        md += ["![median latency against the number of virtual views](images/latency_vs_size.png)", ""]
    notes = read(os.path.join(out, "notes.md"))
    if notes:
        md += ["", notes.strip()]
    md += ["", "## Reproduce", "", "```", "bench/run.sh                          # paper database",
           "HANDDB_BENCH_PCA_LARGE=1 bench/run.sh # also pca-large",
           "HANDDB_BENCH_SCALE=1 bench/run.sh     # also the 10M / 50M synthetic databases", "```", ""]
    with open(args.markdown + ".tmp", "w") as f:
        f.write("\n".join(md))
    os.replace(args.markdown + ".tmp", args.markdown)
    print(f"wrote {args.results} and {args.markdown}")


QUERY_SETS_HOWTO = (
    "The query sets (issue 15, \"measure what users send\"): `query_bench --db DB` also searches real photos "
    "(`--photos DIR`, default /work/shared/photos/asl-digits, searched recursively), a test set's photo-like "
    "and clean label renders (`--testset TS` from `handdb testset`; without it those two sets are skipped with "
    "a note) and the perturbed views of (a). Photos and renders become query points through `handdb query`'s "
    "own input path (`LoadQueryEdges`; label EXRs with the edge options the manifest records). At most "
    "`--set-queries N` (default 20) per set, spread evenly over the sorted files (so over every folder), not "
    "the first N. Each query is searched with `handdb query`'s defaults (top 10, `--hand either`: the query "
    "and its mirror image) and with `--hand right`; a set's lines give the median, p90 (nearest rank) and max "
    "wall time of the search (the input step is reported apart), the median as a ratio to the same run's "
    "perturbed-view median (same hand setting; the sets are searched round-robin, query by query, so load "
    "changes hit them alike), the median CPU time of the search (all threads; steadier on a shared machine) "
    "with its ratio, the share of the searched (view, roll) pairs refined "
    "(`SearchStats::refined`) and the view kd-trees built. Brute force runs on the first `--brute-queries` "
    "queries of each set (one full search per hand; both merged check `either`); a pruned result that differs "
    "makes query_bench exit 1 and name the query on stderr. Example: `query_bench --db DB --threads 2 "
    "--testset TS --set-queries 20 --brute-queries 3`; bench/run.sh runs it after the test sets.")

PCA_LARGE_NOTE = ("Not run in this report (`HANDDB_BENCH_PCA_LARGE=1` runs it). `configs/pca-large.json` is "
                  "22,016 renders (256 PCA shapes x 86 directions; x 48 rolls = 1,056,768 virtual views).")

if __name__ == "__main__":
    main()
