"""qicp: 2D laser scan matching boosted by quad trees.

The matchers, the CARMEN reader and the benchmark metrics of the ``qicp`` command line, from
Python. A log fed through :class:`Matcher` gives the trajectory ``qicp match`` writes::

    import qicp

    m = qicp.Matcher("q-wsm")
    poses = [m.process_record(r) for r in qicp.read_carmen("intel.clf.bz2")]
    traj = [(r.timestamp, *r.pose) for r in poses]
    print(qicp.evaluate_relations(traj, "intel.relations")["trans_mean"])
"""

from ._qicp import (
    Log,
    Matcher,
    MatchResult,
    QicpError,
    Record,
    __version__,
    ate,
    evaluate_relations,
    matcher_names,
    read_bag,
    read_carmen,
    read_tum,
    sweep_report,
    sweep_run,
    sweep_variants,
    write_tum,
)

__all__ = [
    "Log",
    "Matcher",
    "MatchResult",
    "QicpError",
    "Record",
    "__version__",
    "ate",
    "evaluate_relations",
    "matcher_names",
    "read_bag",
    "read_carmen",
    "read_tum",
    "sweep_report",
    "sweep_run",
    "sweep_variants",
    "write_tum",
]
