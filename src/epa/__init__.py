"""epica: trajectory evaluation for SLAM and VIO (import package ``epa``).

Where things live:

- ``readers/``: every way a trajectory comes in (``text``: TUM, KITTI, EuRoC, OpenVINS, CSV;
  ``bags``: ROS 1/2 bags and TF; the package: a source read with its per-source settings).
- ``io``: stage artifacts and the writers of every format.
- ``trajectory``, ``geometry``: the array type and rotation maths.
- Steps: ``sync`` (Step 1 time offset, association), ``calibration`` (Step 2 hand-eye extrinsic),
  ``alignment`` (Step 3 SE3/Sim3/posyaw).
- ``metrics/``: ``accuracy`` (APE, RPE, drift rate), ``drift`` (fail segments, success rate,
  validity), ``consistency`` (NEES, 3σ), ``efficiency`` (frame times, EA-Drift).
- ``pipeline`` (each stage's computation), ``chain`` (the stage sequence, defined once),
  ``grid`` (batches and worker processes for the workflow), ``cases`` (discovery),
  ``settings`` (schema-validated config), ``tables`` (paper tables), ``cli`` (``epa``).
"""

__version__ = "0.1.0"
