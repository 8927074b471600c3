"""Type stubs of the qicp extension module."""

from os import PathLike
from typing import Iterator, Literal, Optional, Sequence, Tuple, Union, final

import numpy as np
import numpy.typing as npt

__all__ = [
    "Amendment",
    "Log",
    "MatchResult",
    "Matcher",
    "QicpError",
    "Record",
    "__version__",
    "ate",
    "evaluate_relations",
    "matcher_names",
    "read_bag",
    "read_carmen",
    "read_tum",
    "reference_relations",
    "sweep_relations",
    "sweep_report",
    "sweep_run",
    "sweep_variants",
    "write_tum",
]

__version__: str

_Pose = Tuple[float, float, float]
"""A planar pose (x m, y m, θ rad)."""

_Trajectory = Union[npt.ArrayLike, Sequence[Tuple[float, float, float, float]]]
"""An N×4 array of (t s, x m, y m, θ rad)."""

_StrPath = Union[str, "PathLike[str]"]

class QicpError(Exception):
    """A refusal of qicp, with the message the command line prints."""

@final
class Amendment:
    """A correction of earlier scans' poses (``MatchResult.amendment``): the pose of scan
    ``first + k`` (counted from the matcher's first scan, 0) moves by ``shares[k]`` of
    ``correction``, applied in the world (on the left)."""

    @property
    def first(self) -> int:
        """The number of the first scan it moves."""
    @property
    def correction(self) -> _Pose:
        """The whole correction in the world, which the re-anchored scan took."""
    @property
    def shares(self) -> npt.NDArray[np.float64]:
        """Per scan from ``first`` on, the share of the correction it takes (0 to 1)."""
    def moved(self, scan: int, pose: _Pose) -> _Pose:
        """``pose`` of scan number ``scan`` moved as this amendment moves that scan."""
    def apply(self, trajectory: list[Tuple[float, ...]]) -> None:
        """Moves in place the poses of ``trajectory``, whose item i is scan i's pose
        (x, y, θ) or a tuple ending in it (t, x, y, θ)."""

@final
class MatchResult:
    """What a matcher says about one scan."""

    @property
    def timestamp(self) -> float:
        """Time of the scan (s)."""
    @property
    def amendment(self) -> Optional[Amendment]:
        """A correction of earlier scans' poses that this scan's re-anchoring spread over the
        stretch that drifted (``[matcher.revisit] deform``), or None: the command line's
        trajectory holds the poses so corrected."""
    @property
    def pose(self) -> _Pose:
        """The robot's pose in the world, as the command line's trajectory has it."""
    @property
    def covariance(self) -> npt.NDArray[np.float64]:
        """3×3 covariance (x, y, θ) of the match, in the reference frame."""
    @property
    def residual(self) -> float:
        """Mean distance of the final pairs (m); NaN for a fallback."""
    @property
    def certainty(self) -> float:
        """The paper's matching certainty sqrt(σxx² + σyy²) (m²); NaN for a fallback."""
    @property
    def fallback(self) -> Optional[str]:
        """Why the pose is odometry's rather than a match's, or None."""
    @property
    def inserted(self) -> bool:
        """Whether the scan entered the reference."""
    @property
    def iterations(self) -> int:
        """Iterations the matcher ran."""
    @property
    def correspondences(self) -> int:
        """Correspondences in the final iteration."""

@final
class Record:
    """One laser record of a log."""

    @property
    def timestamp(self) -> float: ...
    @property
    def ranges(self) -> npt.NDArray[np.float64]:
        """Raw ranges as measured (m)."""
    @property
    def angle_min(self) -> float: ...
    @property
    def angle_increment(self) -> float: ...
    @property
    def range_max(self) -> float: ...
    @property
    def range_min(self) -> float: ...
    @property
    def odometry(self) -> _Pose:
        """Robot pose by odometry."""
    @property
    def truth(self) -> Optional[_Pose]:
        """Robot pose by ground truth, where the log has it."""
    @property
    def laser_offset(self) -> _Pose:
        """Pose of the laser on the robot."""

@final
class Log:
    """The laser records of a log (CARMEN or ROS 2 bag), read as they are asked for."""

    def __iter__(self) -> Iterator[Record]: ...
    def __next__(self) -> Record: ...
    @property
    def records(self) -> int:
        """Records delivered so far."""
    @property
    def skipped_lines(self) -> int:
        """Lines skipped as malformed so far (CARMEN with lenient=True)."""
    @property
    def dropped(self) -> int:
        """Records dropped so far: CARMEN lines far out of time order, bag scans without
        odometry around them."""

@final
class Matcher:
    """A laser-odometry pipeline: feed it scans in time order, get the robot's pose.

    ``Matcher(kind, **sections)`` builds the matcher the registry names ``kind`` (see
    ``matcher_names()``; ``qicp matchers`` lists every parameter), with the TOML sections of
    ``[matcher]`` given as dicts: ``Matcher("q-wsm", icp={"max_dist_start": 0.7})``.
    """

    def __new__(cls, kind: str = "q-wsm", **sections: dict) -> "Matcher": ...
    @staticmethod
    def from_toml(path: _StrPath) -> "Matcher":
        """The matcher a TOML file's ``[matcher]`` describes."""
    @property
    def kind(self) -> str: ...
    def config_toml(self) -> str:
        """The whole configuration, every default filled in, as TOML."""
    def process(
        self,
        ranges: npt.ArrayLike,
        angle_min: float,
        angle_increment: float,
        *,
        odometry: _Pose,
        timestamp: float,
        range_max: float = 81.0,
        range_min: float = 0.0,
        laser_offset: _Pose = (0.0, 0.0, 0.0),
    ) -> MatchResult:
        """Matches one scan; a float64 ``ranges`` is read in place. The GIL is
        released while matching."""
    def process_record(self, record: Record) -> MatchResult:
        """Matches one record of a log, exactly as ``qicp match`` does."""
    def map_points(self) -> npt.NDArray[np.float64]:
        """The reference's points (a boosted matcher's whole map) as an N×2 array (m), without
        those a full cell of the cell cap replaced."""

def read_carmen(
    path: _StrPath,
    *,
    lenient: bool = False,
    max_beams: int = 10000,
    order: Literal["file", "time"] = "file",
    fov_deg: Optional[float] = None,
    max_range: Optional[float] = None,
    min_range: float = 0.0,
) -> Log:
    """Streams the laser records of a CARMEN log (plain or bzip2), in file order (the order
    the laser took them) or, with ``order="time"``, sorted by time. ``fov_deg``,
    ``max_range`` and ``min_range`` describe the laser where the log does not say it right
    (as ``qicp match --fov-deg/--max-range/--min-range``)."""

def read_bag(
    path: _StrPath,
    *,
    scan_topic: str = "/scan",
    odom_topic: Optional[str] = "/odom",
    odom_frame: Optional[str] = None,
    base_frame: str = "base_link",
    max_beams: int = 10000,
) -> Log:
    """Streams the laser records of a ROS 2 bag (MCAP): LaserScan with odometry from a topic
    or, with ``odom_frame``, from /tf, interpolated to each scan's stamp; with
    ``odom_topic=None`` and no ``odom_frame``, every scan at one pose (no odometry)."""

def evaluate_relations(
    trajectory: _Trajectory, relations_path: _StrPath, *, max_dt: float = 0.1
) -> dict:
    """Freiburg benchmark scores (keys of ``qicp eval relations --json``)."""

def ate(
    estimate: _Trajectory,
    truth: _Trajectory,
    *,
    max_dt: float = 0.1,
    rpe_segment_m: float = 1.0,
) -> dict:
    """Origin-aligned ATE, RPE and final error (keys of ``qicp eval ate --json``)."""

def read_tum(path: _StrPath) -> npt.NDArray[np.float64]:
    """A TUM trajectory as an N×4 array."""

def write_tum(path: _StrPath, trajectory: _Trajectory) -> None:
    """Writes a trajectory as TUM, as ``qicp match`` writes ``trajectory.tum``: to a temporary
    file beside ``path``, renamed into place when complete (a failed write leaves no partial
    file, and a link at ``path`` to a regular file is replaced, not followed; a device or a pipe
    there is written to)."""

def matcher_names() -> list[str]:
    """The matcher names the registry resolves."""

def sweep_variants(matcher: str = "q-wsm", *, config: Optional[_StrPath] = None) -> list[str]:
    """The variants ``qicp sweep`` runs for a matcher, in report order (the default aside)."""

def sweep_run(
    log: _StrPath,
    relations: _StrPath,
    variant: str = "default",
    *,
    matcher: str = "q-wsm",
    config: Optional[_StrPath] = None,
    scans: Optional[int] = None,
    lenient: bool = False,
) -> dict:
    """One run of ``qicp sweep``: its figures (the keys of a variant in ``--json``) and
    ``relation_errors``, each relation's translational error (``None`` where the run has no
    pose at its times), with which ``sweep_report`` compares a variant that scored fewer
    relations with the default on the same ones."""

def sweep_relations(
    log: _StrPath,
    out: _StrPath,
    *,
    matcher: str = "q-wsm",
    config: Optional[_StrPath] = None,
    scans: Optional[int] = None,
    lenient: bool = False,
) -> dict:
    """The default run of a sweep on a log without relations (``qicp sweep LOG`` without
    ``--relations``): writes to ``out`` the relations drawn along its trajectory, which the
    variants' ``sweep_run`` calls are scored with, and returns its figures."""

def reference_relations(
    log: _StrPath,
    reference: _StrPath,
    out: _StrPath,
    *,
    scans: Optional[int] = None,
    lenient: bool = False,
) -> int:
    """The relations of a sweep against a reference trajectory (``qicp sweep LOG --reference
    TUM``): writes to ``out`` the segments drawn along the TUM trajectory ``reference``, which
    every run's ``sweep_run`` (the default's too) is scored with, and returns their number."""

def sweep_report(
    log: _StrPath,
    relations: _StrPath,
    results: Sequence[Tuple[str, Union[dict, str]]],
    *,
    matcher: str = "q-wsm",
    config: Optional[_StrPath] = None,
    scans: Optional[int] = None,
    lenient: bool = False,
    against_default: bool = False,
    reference: Optional[_StrPath] = None,
) -> str:
    """The JSON report of ``qicp sweep --json`` from every run's figures or failure message,
    the default first; with ``against_default``, that of a sweep against the default run
    (``relations`` from ``sweep_relations``); with ``reference``, that of ``--reference``
    (``relations`` from ``reference_relations``)."""
