"""Importers: public recordings, in their own layouts, into slipkit's dataset format.

Each importer takes the path of a recording (a file or folder in the source's own
layout) and returns a :class:`~slipkit.data.dataset.Dataset`; ``slipkit import
source=<name> path=... out=...`` calls it through ``configs/source/<name>.yaml``
and writes the dataset folder. Malformed input raises
:class:`~slipkit.errors.SourceFormatError` naming the file (and line and column).

- :func:`read_biotacsp_dos`: BioTacSP-DoS, direction of slip, 24 electrodes at an
  assumed 100 Hz, one trial per sequence.
- :func:`read_bts3v2`: biotacsp-stability-set-v2, grasp stability, 72 electrodes,
  one snapshot trial per grasp.
- :func:`read_robotic_finger`: Robotic-Finger, 19 electrodes and the unit force
  direction, one snapshot trial per sample.
- :func:`read_csv_dataset`: any CSV file or folder of CSVs, one stream.
- :func:`read_rosbag`: ROS 1 and ROS 2 (MCAP, sqlite3) bags, one stream per topic
  (``rosbags`` is imported only when it is called).

See ``docs/importers.md`` for the layouts, assumptions, citations and licenses.
"""

from slipkit.data.importers.biotacsp_dos import read_biotacsp_dos
from slipkit.data.importers.bts3v2 import read_bts3v2
from slipkit.data.importers.csv import read_csv_dataset
from slipkit.data.importers.robotic_finger import read_robotic_finger
from slipkit.data.importers.rosbag import read_rosbag

__all__ = [
    "read_biotacsp_dos",
    "read_bts3v2",
    "read_csv_dataset",
    "read_robotic_finger",
    "read_rosbag",
]
