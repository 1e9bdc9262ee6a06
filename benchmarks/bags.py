"""Reading a pose topic from a large bag costs time in proportion to the topic, not the bag.

    python benchmarks/bags.py [--images 400] [--poses 100000] [--skip-evo]

Writes, in a temporary folder, a ROS 1 bag and a ROS 2 MCAP bag each holding a 100,000-message
PoseStamped topic (200 Hz) and, interleaved over the same 500 s, an image-like topic of
640x480x3 bytes per message (400 messages: ~370 MB), plus the same bags without the images. Reads
the pose topic with ``epa traj`` (in-process, best of 3) and with evo's ``read_bag_trajectory``.
"""

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import bag_fixture  # noqa: E402 - the tests' bag writer

from epa import simulate  # noqa: E402
from epa.core.trajectory import Trajectory  # noqa: E402
from epa.readers import bags  # noqa: E402


def write(path: Path, storage: str, poses: Trajectory, n_images: int) -> None:
    from rosbags.typesys import Stores, get_typestore

    extra = None
    if n_images:
        ts = get_typestore(Stores.ROS1_NOETIC if storage == "ros1" else Stores.ROS2_HUMBLE)
        T = ts.types
        data = np.random.default_rng(0).integers(0, 255, 640 * 480 * 3, dtype=np.uint8)
        stamps = np.linspace(poses.t[0], poses.t[-1], n_images)

        def image(t):
            sec = int(t)
            stamp = T["builtin_interfaces/msg/Time"](sec=sec, nanosec=int((t - sec) * 1e9))
            header = (
                T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id="cam")
                if storage == "ros1"
                else T["std_msgs/msg/Header"](stamp=stamp, frame_id="cam")
            )
            return T["sensor_msgs/msg/Image"](
                header=header,
                height=480,
                width=640,
                encoding="rgb8",
                is_bigendian=0,
                step=640 * 3,
                data=data,
            )

        extra = {
            "/camera/image_raw": (
                "sensor_msgs/msg/Image",
                [(int(t * 1e9), image(t)) for t in stamps],
            )
        }
    bag_fixture.write_bag(
        path, {"/pose": ("geometry_msgs/msg/PoseStamped", poses)}, storage=storage, extra=extra
    )


def size(path: Path) -> int:
    return sum(f.stat().st_size for f in bags.bag_files(path))


def best(fn, repeat=3) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--poses", type=int, default=100_000)
    ap.add_argument("--images", type=int, default=400)
    ap.add_argument("--skip-evo", action="store_true")
    args = ap.parse_args()
    t = 1.7e9 + np.arange(args.poses) / 200.0
    r, p = simulate.truth_pose("drone_figure8", t - t[0])
    poses = Trajectory.from_rp(t, r, p)
    tmp = Path(tempfile.mkdtemp(prefix="epa-bags-"))
    try:
        print(f"{'bag':<28} {'size MB':>8} {'epa s':>7} {'evo s':>7}")
        for storage, name in (("ros1", "b.bag"), ("mcap", "b_mcap")):
            for n_images in (0, args.images):
                path = tmp / f"{n_images}_{name}"
                write(path, storage, poses, n_images)
                ours = best(lambda path=path: bags.read_bag(path, "/pose"))
                assert len(bags.read_bag(path, "/pose")) == args.poses
                evo = float("nan")
                if not args.skip_evo:
                    from evo.tools import file_interface
                    from rosbags.rosbag1 import Reader as R1
                    from rosbags.rosbag2 import Reader as R2

                    def read_evo(path=path, storage=storage):
                        with R1(path) if storage == "ros1" else R2(path) as reader:
                            file_interface.read_bag_trajectory(reader, "/pose")

                    evo = best(read_evo, repeat=1)
                label = f"{storage} poses{' + images' if n_images else ''}"
                print(f"{label:<28} {size(path) / 1e6:8.1f} {ours:7.2f} {evo:7.2f}", flush=True)
                shutil.rmtree(path, ignore_errors=True) if path.is_dir() else path.unlink()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
