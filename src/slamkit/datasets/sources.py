"""Where each real data set comes from: its files, their checksums, their publisher.

slamkit ships no public data (most of it carries no licence from its authors). This module is
the one table a user needs to get it: for every registered real data set (and a few groups of
files the tests, benchmarks and ``slamkit optimize`` read), the files it needs under the data
root, each with its size and SHA-256 (:data:`slamkit.datasets.checksums.FILES`), and for each
file its :class:`Origin` — the publisher's page, the paper to cite, the licence where one is
stated, and how the copy slamkit knows differs from what the publisher distributes.

The checksums are of the files *as they lie in slamkit's data folder* (``.gz`` files
compressed, CSV exports of MATLAB variables, ROS bags converted from CARMEN logs). The
publishers distribute other packagings, so a file fetched from its original page may need the
conversion that :attr:`Origin.packaging` names before it matches. ``slamkit data fetch``
therefore downloads from a *mirror* that has the data folder's layout
(:mod:`slamkit.datasets.fetch`), and without one lists each file's origin and target path.

Origins are found by path prefix (:data:`ORIGINS`, the longest prefix wins), so a file added to
a folder inherits that folder's origin; groups (:data:`GROUPS`) are path prefixes too.
"""

from __future__ import annotations

from dataclasses import dataclass

from slamkit.datasets.checksums import FILES, DataFile
from slamkit.datasets.registry import DATASETS
from slamkit.errors import UnknownNameError

__all__ = [
    "GROUPS",
    "NOT_STATED",
    "ORIGINS",
    "DataSource",
    "Origin",
    "fetchable_names",
    "get_source",
    "list_sources",
    "origin_of",
]

NOT_STATED = "not stated"
"""The licence of a data set whose authors state none (most of them)."""


@dataclass(frozen=True)
class Origin:
    """Who published some files and where: ``url`` is the publisher's page (as given in the
    literature; such pages move), ``citation`` the paper to cite, ``licence`` the one stated
    by the authors (else :data:`NOT_STATED`), ``packaging`` how slamkit's copies differ from
    what that page distributes (empty when they are the same files)."""

    publisher: str
    url: str
    citation: str
    licence: str = NOT_STATED
    packaging: str = ""


_FREIBURG = Origin(
    "SLAM benchmark, Autonomous Intelligent Systems lab, University of Freiburg",
    "http://ais.informatik.uni-freiburg.de/slamevaluation/datasets.php",
    'R. Kümmerle, B. Steder, C. Dornhege, M. Ruhnke, G. Grisetti, C. Stachniss and A. Kleiner, "On '
    'measuring the accuracy of SLAM algorithms", Autonomous Robots 27(4), 387-407, 2009',
)
_FREIBURG_LOGS = Origin(
    _FREIBURG.publisher,
    _FREIBURG.url,
    _FREIBURG.citation,
    packaging="the benchmark distributes the corrected logs as plain-text .log files; here they "
    "are gzipped (compare `zcat FILE | sha256sum`)",
)
_RADISH = Origin(
    "Radish, the Robotics Data Set Repository (A. Howard, N. Roy); corrected logs as published "
    "by the University of Freiburg (C. Stachniss's data set page)",
    "http://www2.informatik.uni-freiburg.de/~stachnis/datasets.html",
    'A. Howard and N. Roy, "The Robotics Data Set Repository (Radish)", '
    "http://radish.sourceforge.net/, 2003; each log's recording is credited on its Radish page",
    packaging="distributed as plain-text corrected CARMEN logs; here gzipped",
)
_ROSBAGS = Origin(
    "SLAM benchmark, University of Freiburg (raw CARMEN .clf logs); converted to ROS 1 bags "
    "for slamkit's data folder",
    "http://ais.informatik.uni-freiburg.de/slamevaluation/datasets.php",
    _FREIBURG.citation,
    packaging="the benchmark distributes raw CARMEN .clf text logs; these bz2-compressed ROS 1 "
    "bags are a conversion of them (scans, raw odometry, original stamps), so only a mirror "
    "of slamkit's data folder has these exact files; slamkit also reads the .clf directly "
    "(`slamkit run ... --data FILE.clf`)",
)
_DPSLAM = Origin(
    "DP-SLAM, A. Eliazar and R. Parr, Duke University",
    "https://users.cs.duke.edu/~parr/dpslam/",
    'A. Eliazar and R. Parr, "DP-SLAM: Fast, robust simultaneous localization and mapping '
    'without predetermined landmarks", IJCAI 2003',
    packaging="distributed as a plain-text log; here gzipped",
)
_MRCLAM = Origin(
    "UTIAS Multi-Robot Cooperative Localization and Mapping Dataset, Autonomous Space Robotics "
    "Lab, University of Toronto",
    "http://asrl.utias.utoronto.ca/datasets/mrclam/",
    'K. Y. K. Leung, Y. Halpern, T. D. Barfoot and H. H. T. Liu, "The UTIAS Multi-Robot '
    'Cooperative Localization and Mapping Dataset", IJRR 30(8), 969-974, 2011',
    packaging="distributed as a zip of plain-text .dat files; Robot1_Odometry.dat is gzipped here",
)
_TRIANGULATION = Origin(
    "Triangulation Toolbox, S. Choi (MRCLAM cut into stationary snapshots)",
    "https://github.com/SunglokChoi/Triangulation-Toolbox",
    "the MRCLAM paper (Leung et al., IJRR 30(8), 2011) and S. Choi's Triangulation Toolbox",
    packaging="the toolbox ships mrclam1.mat; the CSV files are text exports of its variables "
    "landmark, groundtruth and measurement (values unchanged)",
)
_PLAZA = Origin(
    "Range-only data sets, Field Robotics Center, Robotics Institute, Carnegie Mellon "
    "University (also in GTSAM's examples)",
    "http://www.frc.ri.cmu.edu/projects/emergencyresponse/RangeData/",
    'J. Djugash, S. Singh, G. Kantor and W. Zhang, "Range-only SLAM for robots operating '
    'cooperatively with sensor networks", IEEE ICRA 2006',
    packaging="distributed as Plaza1_.mat; the .txt and .csv files are text exports of its "
    "variables DR, TD, GT, TL and DRp (docs/data.md gives the export code)",
)
_ACFR = Origin(
    "Victoria Park data set, Australian Centre for Field Robotics (E. Nebot, J. Guivant), "
    "University of Sydney",
    "http://www-personal.acfr.usyd.edu.au/nebot/victoria_park.htm",
    'J. Guivant and E. Nebot, "Optimization of the simultaneous localization and map-building '
    'algorithm for real-time implementation", IEEE Trans. Robotics and Automation 17(3), 2001',
    packaging="distributed as MATLAB files (aa3_dr.mat, aa3_gpsx.mat); the CSV files are text "
    "exports of their variables, aa3_dr gzipped",
)
_ACFR_ASCII = Origin(
    _ACFR.publisher + " — the ASCII release",
    _ACFR.url,
    _ACFR.citation,
    packaging="distributed as plain-text files (Laser.txt, DRS.txt, GPS.txt, "
    "Sensors_manager.txt); here renamed in lower case and gzipped",
)
_SLSJF = Origin(
    "Sparse Local Submap Joining Filter (SLSJF) data, S. Huang, Z. Wang and G. Dissanayake, "
    "University of Technology Sydney (on OpenSLAM)",
    "https://openslam-org.github.io/slsjf.html",
    'S. Huang, Z. Wang and G. Dissanayake, "Sparse local submap joining filter for building '
    'large-scale maps", IEEE Trans. Robotics 24(5), 2008; and the ACFR Victoria Park data',
    packaging="distributed as .mat files; the .csv.gz files are gzipped text exports of them",
)
_ISAM = Origin(
    "iSAM data sets, M. Kaess (MIT CSAIL)",
    "http://people.csail.mit.edu/kaess/isam/",
    'M. Kaess, A. Ranganathan and F. Dellaert, "iSAM: Incremental smoothing and mapping", '
    "IEEE Trans. Robotics 24(6), 2008",
    licence=NOT_STATED + " for the data (the iSAM library is LGPL)",
)
_GTSAM = Origin(
    "GTSAM's example data (examples/Data), Georgia Tech BORG lab",
    "https://github.com/borglab/gtsam/tree/develop/examples/Data",
    'F. Dellaert and GTSAM contributors, "borglab/gtsam", Georgia Tech Borg Lab; Victoria Park '
    "after Guivant and Nebot (2001)",
    licence=NOT_STATED + " for the data (the GTSAM repository is BSD-licensed)",
)
_SESYNC = Origin(
    "pose-graph benchmarks as collected by L. Carlone and by SE-Sync (D. M. Rosen)",
    "https://lucacarlone.mit.edu/datasets/",
    'D. M. Rosen, L. Carlone, A. S. Bandeira and J. J. Leonard, "SE-Sync: A certifiably correct '
    'algorithm for synchronization over the special Euclidean group", IJRR 38(2-3), 2019; '
    'L. Carlone, R. Tron, K. Daniilidis and F. Dellaert, "Initialization techniques for 3D SLAM", '
    "IEEE ICRA 2015",
    packaging="the g2o files of SE-Sync's evaluation (SE-Sync's published optima hold for "
    "these exact files; https://github.com/david-m-rosen/SE-Sync) and Carlone's page, not "
    "checked byte for byte against either; originally Intel/MIT/CSAIL from Radish and g2o, "
    "M3500 from E. Olson, city10000 and sphere2500 from iSAM, parking-garage from g2o",
)
_CARLONE = Origin(
    "planar pose-graph data sets of L. Carlone",
    "https://lucacarlone.mit.edu/datasets/",
    'L. Carlone, R. Aragues, J. A. Castellanos and B. Bona, "A fast and accurate approximation '
    'for planar pose graph optimization", IJRR 33(7), 2014',
)
_HOGMAN = Origin(
    "TORO / HOG-Man examples, G. Grisetti et al. (OpenSLAM)",
    "https://openslam-org.github.io/hog-man.html",
    'G. Grisetti, R. Kümmerle, C. Stachniss, U. Frese and C. Hertzberg, "Hierarchical '
    'optimization on manifolds for online 2D and 3D mapping", IEEE ICRA 2010',
)
_VERTIGO = Origin(
    "Vertigo robust back-end data sets, N. Sünderhauf (OpenSLAM)",
    "https://github.com/OpenSLAM-org/openslam_vertigo",
    'N. Sünderhauf and P. Protzel, "Switchable constraints for robust pose graph SLAM", '
    "IEEE/RSJ IROS 2012",
    licence="GPL-3.0-or-later (the licence of the Vertigo repository; the data in it, from "
    "E. Olson, g2o and iSAM, state none of their own)",
    packaging="the repository's datasets/NAME/KIND/FILE paths are flattened here to "
    "NAME__KIND__FILE",
)

ORIGINS: dict[str, Origin] = {
    "isam/": _ISAM,
    "landmarks/example_gtsam_BR.graph": _GTSAM,
    "landmarks/victoria_park/victoria_park_gtsam.txt": _GTSAM,
    "landmarks/plaza/": _PLAZA,
    "landmarks/utias_mrclam/MRCLAM_Dataset1/": _MRCLAM,
    "landmarks/utias_mrclam/triangulation_toolbox/": _TRIANGULATION,
    "landmarks/victoria_park/original_acfr/": _ACFR,
    "landmarks/victoria_park/raw_laser/": _ACFR_ASCII,
    "landmarks/victoria_park/slsjf/": _SLSJF,
    "laser/corrected_carmen/": _RADISH,
    "laser/corrected_carmen/intel-corrected.log.gz": _FREIBURG_LOGS,
    "laser/corrected_carmen/aces-corrected.log.gz": _FREIBURG_LOGS,
    "laser/corrected_carmen/freiburg-079-corrected.log.gz": _FREIBURG_LOGS,
    "laser/relations/": _FREIBURG,
    "laser/rosbags/": _ROSBAGS,
    "laser/dpslam/": _DPSLAM,
    "posegraph2d/": _SESYNC,
    "posegraph2d/w100.graph": _HOGMAN,
    "posegraph2d/README-hogman-fileformat-2D.txt": _HOGMAN,
    "posegraph2d/carlone/": _CARLONE,
    "posegraph2d/vertigo/": _VERTIGO,
    "posegraph3d/": _SESYNC,
    "posegraph3d/README-hogman-fileformat-3D.txt": _HOGMAN,
}
"""Path prefix under the data root (a folder ending in ``/``, or one file) → its origin; the
longest matching prefix names a file's origin (:func:`origin_of`)."""

GROUPS: dict[str, tuple[tuple[str, ...], str]] = {
    "corrected-carmen": (
        ("laser/corrected_carmen/",),
        "all eleven corrected CARMEN logs: acapulco, aces, belgioioso, edmonton, fhw, "
        "freiburg-079, freiburg-101, freiburg-campus, intel, orebro, seattle",
    ),
    "victoria-park-raw": (
        ("landmarks/victoria_park/raw_laser/",),
        "Victoria Park's raw laser (ASCII release): 7230 scans × 361 beams, speed and "
        "steering, GPS, the sensors' order",
    ),
    "freiburg-relations": (
        ("laser/relations/",),
        "the Freiburg benchmark's reference relations of Intel, ACES and Freiburg 079",
    ),
    "posegraph2d": (
        ("posegraph2d/",),
        "2D pose graphs: Intel, MIT, CSAIL, M3500, City10000 (SE-Sync's), w100, Carlone's "
        "versions and Vertigo's robust-back-end sets",
    ),
    "posegraph3d": (
        ("posegraph3d/",),
        "3D pose graphs: sphere2500, torus3D, parking-garage, smallGrid3D, tinyGrid3D",
    ),
    "isam": (("isam/",), "iSAM's data sets: M3500, cityTrees10000, victoriaPark, sphere2500"),
    "plaza": (("landmarks/plaza/",), "CMU Plaza 1 with the original .mat and the DR path"),
    "mrclam-toolbox": (
        ("landmarks/utias_mrclam/triangulation_toolbox/",),
        "the Triangulation Toolbox's MRCLAM snapshots with its .mat and README",
    ),
    "victoria-park-all": (
        ("landmarks/victoria_park/original_acfr/", "landmarks/victoria_park/slsjf/"),
        "Victoria Park's MATLAB files, their CSV exports and the SLSJF data",
    ),
    "gtsam-examples": (
        ("landmarks/example_gtsam_BR.graph", "landmarks/victoria_park/victoria_park_gtsam.txt"),
        "GTSAM's bearing-range example graph and its Victoria Park graph",
    ),
}
"""Named groups of files that are not (or not only) one registered data set → (path
prefixes, description). ``slamkit data fetch GROUP`` fetches all of a group's files.
``victoria-park-raw`` is the registered ``victoria-park-laser`` and its documentation."""


@dataclass(frozen=True)
class DataSource:
    """The files one name needs under the data root and where they come from. ``files``
    lists each path with its size and SHA-256; ``unknown`` the paths a registry entry names
    that the checksum table lacks (an error the tests catch; such files are only checked
    for existence)."""

    name: str
    description: str
    files: tuple[DataFile, ...]
    unknown: tuple[str, ...] = ()

    @property
    def size(self) -> int:
        """Total size in bytes of the files with checksums."""
        return sum(f.size for f in self.files)

    @property
    def paths(self) -> tuple[str, ...]:
        """Every relative path, with checksum or not."""
        return tuple(f.path for f in self.files) + self.unknown

    def origins(self) -> list[Origin]:
        """The distinct origins of the files, in file order."""
        seen: list[Origin] = []
        for path in self.paths:
            origin = origin_of(path)
            if origin is not None and origin not in seen:
                seen.append(origin)
        return seen


def origin_of(path: str) -> Origin | None:
    """The origin of the file at ``path`` (relative, ``/``-separated): the one of the longest
    prefix in :data:`ORIGINS`; ``None`` when no prefix matches."""
    best = max((p for p in ORIGINS if path.startswith(p)), key=len, default=None)
    return None if best is None else ORIGINS[best]


def _expand(prefixes: tuple[str, ...]) -> tuple[str, ...]:
    return tuple(sorted(p for p in FILES if p.startswith(prefixes)))


def _source(name: str, description: str, paths: tuple[str, ...]) -> DataSource:
    known = tuple(FILES[p] for p in paths if p in FILES)
    return DataSource(name, description, known, tuple(p for p in paths if p not in FILES))


def fetchable_names() -> list[str]:
    """The names ``slamkit data fetch`` takes: every registered real data set, then every
    group that is not also a registered name."""
    real = [e.name for e in DATASETS.values() if e.kind == "real"]
    return real + [g for g in GROUPS if g not in DATASETS]


def get_source(name: str) -> DataSource:
    """The files and origins of a registered real data set (its registry entry's files) or
    of a group. A simulated data set has no files (an empty source); an unknown name raises
    :class:`~slamkit.errors.UnknownNameError` listing the names there are."""
    entry = DATASETS.get(name)
    if entry is not None:
        return _source(name, entry.description, entry.files)
    if name in GROUPS:
        prefixes, description = GROUPS[name]
        return _source(name, description, _expand(prefixes))
    raise UnknownNameError("real data set or group", name, fetchable_names())


def list_sources() -> list[DataSource]:
    """The source of every name in :func:`fetchable_names`, in that order."""
    return [get_source(n) for n in fetchable_names()]
