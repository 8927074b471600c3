"""qicp: 2D laser scan matching boosted by quad trees.

The matchers, the CARMEN reader and the benchmark metrics of the ``qicp`` command line, from
Python. A log fed through :class:`Matcher` gives the trajectory ``qicp match`` writes::

    import qicp

    m = qicp.Matcher("q-wsm")
    traj = []
    for r in qicp.read_carmen("intel.clf.bz2"):
        res = m.process_record(r)
        if res.amendment is not None:  # a re-anchoring spread over the poses before it
            res.amendment.apply(traj)
        traj.append((res.timestamp, *res.pose))
    print(qicp.evaluate_relations(traj, "intel.relations")["trans_mean"])
"""

# The extension lists its names once (`_qicp.__all__`, typed in `_qicp.pyi`); the package
# re-exports exactly those.
from ._qicp import *  # noqa: F401,F403
from ._qicp import __all__ as __all__
