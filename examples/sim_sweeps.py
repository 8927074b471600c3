"""Robustness sweeps on simulated worlds, scored against their ground truth.

    python examples/sim_sweeps.py WORLD.toml [--worlds N] [--matcher KIND ...] [--config FILE]
                                  [--variants NAMES] [--max-scans N] [--jobs N] [--out DIR]

Simulates N drives of one world configuration (`configs/worlds/*.toml`), the layout seeds and
noise seeds numbered as `qicp run --worlds N` numbers its worlds (the config's own seeds, then
one more each world), and runs `qicp sweep` on each drive against its ground truth
(`--reference groundtruth.tum`: relations drawn along the true path, a segment per metre or
30°, and a revisit wherever it comes back within a metre of a pose a minute or more older).
These are logs nobody tuned on: a parameter variant that breaks here breaks for reasons the
Intel log cannot show.

Prints one line per world and matcher, then per matcher: the parameter variants (names with
`*`) over their bound, max(2 x default, 0.05 m), out of all run, and the input variants over
theirs by name. `--out DIR` keeps each drive (`DIR/world-<layout seed>/sim/`) and report
(`DIR/world-<layout seed>/<matcher>.json`) and writes `DIR/summary.json`.
"""

import argparse
import json
import math
import os
import pathlib
import subprocess
import sys
import tempfile

REPO = pathlib.Path(__file__).resolve().parents[1]


def qicp_binary():
    """QICP_BIN, else this repository's release build, else `qicp` on the PATH."""
    if "QICP_BIN" in os.environ:
        return os.environ["QICP_BIN"]
    built = REPO / "target" / "release" / "qicp"
    return str(built) if built.is_file() else "qicp"


def config_seeds(path):
    """The drive config's `[world] seed` and `[drive] seed` (None where not given or not
    readable: tomllib needs Python 3.11)."""
    try:
        import tomllib
    except ImportError:
        return None, None
    with open(path, "rb") as f:
        cfg = tomllib.load(f)
    return cfg.get("world", {}).get("seed"), cfg.get("drive", {}).get("seed")


def run(cmd):
    done = subprocess.run([str(c) for c in cmd], capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"{' '.join(map(str, cmd))} failed:\n{done.stderr}")
    return done.stdout


def tally(report):
    """(parameter variants over the bound, parameter variants, input variants over) of one
    sweep report."""
    bound = max(2.0 * report["default"]["trans_mean"], 0.05)
    params = [v for v in report["variants"] if "*" in v["name"]]
    over = lambda v: not v["trans_mean"] <= bound  # noqa: E731  (a NaN is over)
    inputs_over = [v["name"] for v in report["variants"] if "*" not in v["name"] and over(v)]
    return sum(map(over, params)), len(params), inputs_over


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("world", help="drive configuration, e.g. configs/worlds/park.toml")
    parser.add_argument("--worlds", type=int, default=10, help="drives to simulate (default 10)")
    parser.add_argument("--world-seed", type=int, help="first layout seed (default: the config's)")
    parser.add_argument("--seed", type=int, help="first noise seed (default: the config's)")
    parser.add_argument("--matcher", action="append", help="matcher kind (repeatable; default q-wsm and q-idc)")
    parser.add_argument("--config", help="TOML with a [matcher] table, given to every sweep")
    parser.add_argument("--variants", help="only these variants (comma-separated, as `qicp sweep`)")
    parser.add_argument("--max-scans", type=int, help="stop each drive after this many scans")
    parser.add_argument("--jobs", type=int, help="runs at a time within each sweep (default: all cores)")
    parser.add_argument("--out", help="keep the drives and reports here (default: a temporary directory)")
    args = parser.parse_args()
    if args.worlds < 1:
        sys.exit("--worlds must be at least 1")
    world_seed, seed = config_seeds(args.world)
    world_seed = args.world_seed if args.world_seed is not None else world_seed
    seed = args.seed if args.seed is not None else seed
    if world_seed is None or seed is None:
        sys.exit("give --world-seed and --seed (the config has none, or Python < 3.11 cannot read it)")
    matchers = args.matcher or ["q-wsm", "q-idc"]
    qicp = qicp_binary()

    scratch = None if args.out else tempfile.TemporaryDirectory(prefix="qicp-sim-sweeps-")
    out = pathlib.Path(args.out or scratch.name)
    results = {m: [] for m in matchers}
    for k in range(args.worlds):
        layout, noise = world_seed + k, seed + k
        here = out / f"world-{layout}"
        print(f"world {layout} (noise seed {noise}): simulating", file=sys.stderr)
        sim = ["sim", args.world, "--world-seed", layout, "--seed", noise, "--out", here / "sim"]
        if args.max_scans is not None:
            sim += ["--max-scans", args.max_scans]
        run([qicp, *sim])
        for m in matchers:
            print(f"world {layout}: sweeping {m}", file=sys.stderr)
            sweep = ["sweep", here / "sim" / "sim.log", "--matcher", m, "--json",
                     "--reference", here / "sim" / "groundtruth.tum"]
            for flag, value in [("--config", args.config), ("--variants", args.variants),
                                ("--jobs", args.jobs)]:
                if value is not None:
                    sweep += [flag, value]
            text = run([qicp, *sweep])
            (here / f"{m}.json").write_text(text)
            report = json.loads(text)
            over, params, inputs_over = tally(report)
            d = report["default"]
            row = {
                "world_seed": layout, "noise_seed": noise, "default_trans_mean": d["trans_mean"],
                "default_trans_max": d["trans_max"], "parameter_variants": params,
                "parameter_variants_over": over, "input_variants_over": inputs_over,
                "worst_variant": report["worst_variant"], "worst_ratio": report["worst_ratio"],
                "median_ratio": report["median_ratio"],
            }
            results[m].append(row)
            print(f"world {layout:3} {m:8} default {d['trans_mean']:.4f} m (max {d['trans_max']:.2f})"
                  f"  parameters over {over} of {params}  inputs over {','.join(inputs_over) or '-'}"
                  f"  median ratio {report['median_ratio']:.2f}")

    summary = {"world": str(args.world), "worlds": args.worlds, "matchers": {}}
    print()
    for m, rows in results.items():
        means = [r["default_trans_mean"] for r in rows if r["default_trans_mean"] > 0]
        gm = math.exp(sum(map(math.log, means)) / len(means)) if means else float("nan")
        inputs = {}
        for r in rows:
            for name in r["input_variants_over"]:
                inputs[name] = inputs.get(name, 0) + 1
        s = {
            "default_geomean_trans_mean": gm,
            "parameter_variants_over": sum(r["parameter_variants_over"] for r in rows),
            "parameter_variants": sum(r["parameter_variants"] for r in rows),
            "worlds_with_an_input_variant_over": inputs,
            "runs": rows,
        }
        summary["matchers"][m] = s
        print(f"{m}: {len(rows)} worlds, defaults' geometric mean {gm:.4f} m; parameter variants "
              f"over their bound {s['parameter_variants_over']} of {s['parameter_variants']}; "
              f"input variants over (worlds): {inputs or 'none'}")
    if args.out:
        (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    if scratch:
        scratch.cleanup()


if __name__ == "__main__":
    main()
