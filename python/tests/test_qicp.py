"""The Python package gives the command line's answers: trajectories, figures and errors."""

import json
import math
import threading

import numpy as np
import pytest

import qicp
from conftest import INTEL_RELATIONS, run_cli


def first_records(log, n):
    records = []
    for r in qicp.read_carmen(log):
        records.append(r)
        if len(records) == n:
            break
    return records


def test_intel_q_wsm_trajectory_is_the_command_lines_byte_for_byte(intel, qicp_bin, tmp_path):
    cli = run_cli(qicp_bin, "match", intel, "--matcher", "q-wsm", "--out", tmp_path / "cli")
    assert cli.returncode == 0, cli.stderr
    m = qicp.Matcher("q-wsm")
    traj = []
    for r in qicp.read_carmen(intel):
        res = m.process_record(r)
        # A re-anchoring spread over the stretch before it moves those poses too.
        if res.amendment is not None:
            res.amendment.apply(traj)
        traj.append((res.timestamp, *res.pose))
    qicp.write_tum(tmp_path / "py.tum", traj)
    assert (tmp_path / "py.tum").read_bytes() == (tmp_path / "cli" / "trajectory.tum").read_bytes()
    summary = json.loads((tmp_path / "cli" / "summary.json").read_text())
    assert m.map_points().shape == (summary["map_points"], 2)

    # The figures of the file are the command line's, to the last bit (TUM stores the heading
    # as a quaternion, so the poses in memory score within rounding of them).
    py = qicp.evaluate_relations(qicp.read_tum(tmp_path / "py.tum"), INTEL_RELATIONS)
    ev = run_cli(qicp_bin, "eval", "relations", tmp_path / "py.tum", INTEL_RELATIONS, "--json")
    assert ev.returncode == 0, ev.stderr
    assert py == json.loads(ev.stdout)
    in_memory = qicp.evaluate_relations(traj, INTEL_RELATIONS)
    assert all(math.isclose(in_memory[k], py[k], rel_tol=1e-9) for k in py)
    assert py["n"] > 2900 and py["trans_mean"] < 0.05


def test_a_reanchoring_spread_over_intels_first_loop_amends_the_poses_before_it(intel):
    # As tests/intel_matching.rs: the first loop's revisit re-anchors q-wsm once; spread over
    # the loop, no relation of the first 2,500 records is off by the jump (0.43 m).
    m = qicp.Matcher("q-wsm", revisit={"deform": True})
    traj, amendments = [], []
    for r in first_records(intel, 2500):
        res = m.process_record(r)
        if res.amendment is not None:
            amendments.append((len(traj), res.amendment))
            res.amendment.apply(traj)
        traj.append((res.timestamp, *res.pose))
    assert len(amendments) == 1
    at, a = amendments[0]
    # The stretch ends at the record re-anchored (1,835; 1,865 before q-wsm's novelty gate).
    assert at == 1835
    assert 0 < a.first and a.first + len(a.shares) == at
    assert a.shares[0] >= 0.0 and a.shares[-1] == 1.0
    assert all(x <= y for x, y in zip(a.shares, a.shares[1:]))
    # A scan before the stretch keeps its pose; the last one takes the whole correction.
    assert a.moved(a.first - 1, (1.0, 2.0, 0.5)) == (1.0, 2.0, 0.5)
    x, y, theta = a.correction
    assert abs(x) + abs(y) > 0.1
    report = qicp.evaluate_relations(traj, INTEL_RELATIONS)
    assert report["n"] == 401 and report["trans_max"] < 0.15, report


def test_arrays_in_give_the_poses_of_records_in(intel):
    records = first_records(intel, 400)
    by_record, by_array = qicp.Matcher("q-wsm"), qicp.Matcher("q-wsm")
    for i, r in enumerate(records):
        ranges = r.ranges
        if i % 2:
            ranges = np.array(ranges[::-1])[::-1]  # a strided view: converted, same values
        if i % 3 == 0:
            ranges = list(ranges)  # a plain sequence is converted
        a = by_record.process_record(r)
        b = by_array.process(
            ranges,
            r.angle_min,
            r.angle_increment,
            odometry=r.odometry,
            timestamp=r.timestamp,
            range_max=r.range_max,
            range_min=r.range_min,
            laser_offset=r.laser_offset,
        )
        assert a.pose == b.pose
        assert np.array_equal(a.covariance, b.covariance, equal_nan=True)
    assert np.array_equal(by_record.map_points(), by_array.map_points())


def test_float32_ranges_are_taken():
    m = qicp.Matcher("wsm")
    ranges = np.full(181, 2.0, dtype=np.float32)
    r = m.process(ranges, -math.pi / 2, math.pi / 180, odometry=(1.0, 2.0, 0.5), timestamp=3.0)
    assert r.fallback == "empty reference" and r.pose == (1.0, 2.0, 0.5)


def test_results_carry_pose_covariance_and_checks(intel):
    m = qicp.Matcher("q-wsm")
    results = [m.process_record(r) for r in first_records(intel, 200)]
    assert results[0].fallback == "empty reference"
    assert math.isnan(results[0].residual)
    matched = [r for r in results if r.fallback is None]
    assert len(matched) > 190
    for r in matched:
        c = r.covariance
        assert c.shape == (3, 3) and np.allclose(c, c.T) and np.all(np.linalg.eigvalsh(c) > 0)
        assert 0 < r.residual < 0.1 and r.certainty > 0 and r.correspondences > 50
    points = m.map_points()
    # Several scans' points (a scan holds at most 180): 840 here, the surface band keeping
    # out what lands on walls already held.
    assert points.ndim == 2 and points.shape[1] == 2 and len(points) > 500


def test_two_threads_match_as_one(intel):
    records = first_records(intel, 300)
    alone = qicp.Matcher("q-idc")
    expected = [alone.process_record(r).pose for r in records]
    got = {}

    def work(name):
        m = qicp.Matcher("q-idc")
        got[name] = [m.process_record(r).pose for r in records]

    threads = [threading.Thread(target=work, args=(k,)) for k in ("a", "b")]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert got["a"] == expected and got["b"] == expected


def test_sections_set_parameters_and_bad_ones_are_refused():
    m = qicp.Matcher("q-wsm", icp={"max_dist_start": 0.7}, relevance={"tau_max": 0.2})
    assert "max_dist_start = 0.7" in m.config_toml()
    assert "tau_max = 0.2" in m.config_toml()
    with pytest.raises(qicp.QicpError, match="max_dist_start"):
        qicp.Matcher("q-wsm", icp={"max_dist_start": -1.0})
    with pytest.raises(qicp.QicpError, match="no_such_key"):
        qicp.Matcher("q-wsm", icp={"no_such_key": 1.0})
    with pytest.raises(qicp.QicpError, match="as a dict"):
        qicp.Matcher("q-wsm", icp=0.7)
    assert {"q-wsm", "q-idc", "plicp", "q-plicp", "kd-wsm"} <= set(qicp.matcher_names())


def test_errors_carry_the_command_lines_message(intel, qicp_bin, tmp_path):
    with pytest.raises(qicp.QicpError) as err:
        qicp.Matcher("no-such-matcher")
    cli = run_cli(qicp_bin, "match", intel, "--matcher", "no-such-matcher", "--out", tmp_path)
    assert cli.returncode != 0
    assert f"Error: {err.value}" in cli.stderr

    empty = tmp_path / "empty.clf"
    empty.write_text("# nothing but a comment\n")
    with pytest.raises(qicp.QicpError) as err:
        list(qicp.read_carmen(empty))
    cli = run_cli(qicp_bin, "match", empty, "--matcher", "wsm", "--out", tmp_path / "o")
    assert cli.returncode != 0
    assert str(err.value).splitlines()[0] in cli.stderr


def test_bad_input_raises_instead_of_crashing(tmp_path):
    bad = tmp_path / "bad.clf"
    bad.write_text("FLASER 3 1.0 2.0\n")
    with pytest.raises(qicp.QicpError, match="bad.clf:1: FLASER"):
        list(qicp.read_carmen(bad))
    with pytest.raises(qicp.QicpError):
        qicp.read_carmen(tmp_path / "missing.clf")
    with pytest.raises(qicp.QicpError, match="order"):
        qicp.read_carmen(bad, order="sideways")
    m = qicp.Matcher("wsm")
    with pytest.raises(qicp.QicpError, match="max_range"):
        m.process([1.0, 2.0], -0.5, 0.1, odometry=(0, 0, 0), timestamp=0.0, range_max=math.inf)
    with pytest.raises(qicp.QicpError, match="odometry"):
        m.process([1.0, 2.0], -0.5, 0.1, odometry=(math.nan, 0, 0), timestamp=0.0)
    with pytest.raises(qicp.QicpError, match="beams"):
        m.process(np.ones(20_001), -0.5, 1e-4, odometry=(0, 0, 0), timestamp=0.0)
    with pytest.raises(qicp.QicpError, match="4 columns"):
        qicp.ate([(0.0, 1.0, 2.0)], [(0.0, 1.0, 2.0)])


def test_write_tum_replaces_a_file_whole_or_not_at_all(tmp_path):
    out = tmp_path / "est.tum"
    out.write_text("old contents\n")
    with pytest.raises(qicp.QicpError, match="4 columns"):
        qicp.write_tum(out, [(0.0, 1.0, 2.0)])
    assert out.read_text() == "old contents\n", "a refused trajectory leaves the old file"
    with pytest.raises(qicp.QicpError, match="missing"):
        qicp.write_tum(tmp_path / "missing" / "est.tum", [(0.0, 1.0, 2.0, 0.0)])
    qicp.write_tum(out, [(0.0, 1.0, 2.0, 0.0), (1.0, 2.0, 2.0, 0.0)])
    assert len(out.read_text().splitlines()) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["est.tum"], "no temporary file is left"
    # The file is renamed into place, not written through whatever lies at the path: a link
    # planted there is replaced, and the file it points to is left alone.
    other = tmp_path / "other.txt"
    other.write_text("someone else's\n")
    out.unlink()
    out.symlink_to(other)
    qicp.write_tum(out, [(0.0, 1.0, 2.0, 0.0)])
    assert other.read_text() == "someone else's\n"
    assert not out.is_symlink() and len(out.read_text().splitlines()) == 1


def test_ate_is_the_command_lines(intel, qicp_bin, tmp_path):
    truth = [(float(t), math.cos(t / 10) * t, math.sin(t / 10) * t, t / 10) for t in range(200)]
    est = [(t, x + 0.01 * math.sin(t), y, th + 0.001 * t) for t, x, y, th in truth]
    qicp.write_tum(tmp_path / "est.tum", est)
    qicp.write_tum(tmp_path / "truth.tum", truth)
    cli = run_cli(qicp_bin, "eval", "ate", tmp_path / "est.tum", tmp_path / "truth.tum", "--json")
    assert cli.returncode == 0, cli.stderr
    py = qicp.ate(qicp.read_tum(tmp_path / "est.tum"), qicp.read_tum(tmp_path / "truth.tum"))
    assert py == json.loads(cli.stdout)
    assert qicp.ate(truth, truth)["ate_rmse_m"] == 0.0


def test_a_reference_of_another_log_draws_no_relations_and_writes_nothing(intel, tmp_path):
    # One pose far from the log's times: no segment, refused before anything is written.
    reference = tmp_path / "other.tum"
    reference.write_text("1 0 0 0 0 0 0 1\n2 5 0 0 0 0 0 1\n")
    out = tmp_path / "drawn.relations"
    with pytest.raises(qicp.QicpError, match="is it this log's"):
        qicp.reference_relations(intel, reference, out, scans=100)
    assert not out.exists() and list(tmp_path.iterdir()) == [reference]


def test_laser_options_describe_a_log_as_the_command_line_does(tmp_path):
    log = tmp_path / "laser.clf"
    ranges = " ".join(["2.0", "29.5"] * 45)
    log.write_text(f"FLASER 90 {ranges} 0 0 0 0 0 0 1.0 host 1.0\n")
    (r,) = list(qicp.read_carmen(log))
    assert (r.range_max, r.range_min, r.angle_min) == (81.0, 0.0, -math.pi / 2)
    (r,) = list(qicp.read_carmen(log, fov_deg=90.0, max_range=29.495, min_range=0.1))
    assert (r.range_max, r.range_min) == (29.495, 0.1)
    assert math.isclose(r.angle_min, -math.pi / 4)
    with pytest.raises(qicp.QicpError, match="max_range"):
        qicp.read_carmen(log, max_range=-1.0)
