"""`examples/ray_sweep.py` on a local Ray instance writes the report `qicp sweep` writes: the
same runs with the same figures (all but the wall times), ratios and summary."""

import json
import subprocess
import sys


from conftest import INTEL_RELATIONS, REPO, run_cli

import ray  # noqa: F401  (the example needs it; CI installs it)

SCANS = "1500"
VARIANTS = "scans/2,odom-bias,icp.max_dist_start*0.7,relevance.tau_max*1.4,nope.nothing*0.7"


def without_times(report):
    report = dict(report)
    for run in [report["default"], *report["variants"]]:
        run.pop("ms_per_scan_median", None)
    return report


def test_the_ray_sweep_reports_what_qicp_sweep_reports(intel, qicp_bin, tmp_path):
    variants = VARIANTS.rsplit(",", 1)[0]  # the last name is unknown: both refuse it
    cli = run_cli(
        qicp_bin, "sweep", intel, "--matcher", "q-wsm", "--relations", INTEL_RELATIONS,
        "--scans", SCANS, "--variants", variants, "--json", "--jobs", "2",
    )
    assert cli.returncode == 0, cli.stderr
    out = tmp_path / "ray.json"
    script = [sys.executable, str(REPO / "examples" / "ray_sweep.py"), str(intel), str(INTEL_RELATIONS)]
    opts = ["--matcher", "q-wsm", "--scans", SCANS, "--address", "local"]
    done = subprocess.run([*script, *opts, "--variants", variants, "--out", str(out)],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    ours, theirs = json.loads(out.read_text()), json.loads(cli.stdout)
    assert without_times(ours) == without_times(theirs)
    assert [v["name"] for v in ours["variants"]] == variants.split(",")
    assert ours["default"]["trans_mean"] < 0.05

    refused = subprocess.run([*script, *opts, "--variants", VARIANTS], capture_output=True, text=True)
    assert refused.returncode != 0 and "unknown variants nope.nothing*0.7" in refused.stderr


def drawn_sweep(intel, qicp_bin, tmp_path, variants, *scored):
    """`qicp sweep` and the Ray sweep without a relations file (`scored`: `--reference TUM`, or
    nothing for the default run's relations); checks that both report alike and that the drawn
    relations are the segments the runs were scored with. Returns the report, the script and
    its options."""
    common = ["--matcher", "q-wsm", "--scans", SCANS, "--variants", variants, *map(str, scored)]
    cli = run_cli(qicp_bin, "sweep", intel, *common, "--json", "--jobs", "2")
    assert cli.returncode == 0, cli.stderr
    out, drawn = tmp_path / "ray.json", tmp_path / "drawn.relations"
    script = [sys.executable, str(REPO / "examples" / "ray_sweep.py"), str(intel)]
    opts = [*common, "--address", "local"]
    done = subprocess.run([*script, *opts, "--out", str(out), "--drawn-relations", str(drawn)],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    ours, theirs = json.loads(out.read_text()), json.loads(cli.stdout)
    assert without_times(ours) == without_times(theirs)
    assert len([l for l in drawn.read_text().splitlines() if l.strip()]) == ours["relations_total"]
    return ours, script, opts


def test_the_ray_sweep_without_relations_reports_what_qicp_sweep_reports(intel, qicp_bin, tmp_path):
    ours, _, _ = drawn_sweep(intel, qicp_bin, tmp_path, "scans/2,odom-bias,relevance.tau_max*1.4")
    assert ours["scored_against"] == "default run"
    assert ours["default"]["trans_mean"] < 1e-9
    assert all(v["ratio"] is None for v in ours["variants"])


def test_the_ray_sweep_against_a_reference_reports_what_qicp_sweep_reports(intel, qicp_bin, tmp_path):
    # idc's trajectory as the reference, q-wsm swept against it.
    matched = run_cli(qicp_bin, "match", intel, "--matcher", "idc", "--out", tmp_path / "idc")
    assert matched.returncode == 0, matched.stderr
    reference = tmp_path / "idc" / "trajectory.tum"
    ours, script, opts = drawn_sweep(
        intel, qicp_bin, tmp_path, "scans/2,relevance.tau_max*1.4", "--reference", reference
    )
    assert ours["scored_against"] == "reference trajectory"
    assert ours["reference"] == str(reference)
    # q-wsm disagrees with idc's drift: the default is scored, not zero, and has ratios.
    assert ours["default"]["trans_mean"] > 0.0
    assert all(v["ratio"] is not None for v in ours["variants"])

    both = subprocess.run([*script, str(INTEL_RELATIONS), *opts], capture_output=True, text=True)
    assert both.returncode != 0 and "cannot be used together" in both.stderr
