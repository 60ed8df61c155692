#!/usr/bin/python3
"""Writes one recording (EuRoC layout) as ROS bags of every kind the C++ reader takes, with
writers that share no code with it: ROS 1 bags through python3-rosbag, ROS 2 bags (MCAP,
sqlite3) through this folder's own MCAP writer and CDR serializer.

    write_bags.py RECORDING OUT_DIR [--only NAME...] [--jobs N]

Writes into OUT_DIR (each NAME below; all without --only):
    ros1          ros1.bag         Imu + Image (mono8), uncompressed chunks
    ros1-lz4      ros1-lz4.bag     the same, lz4 chunks
    ros1-bz2      ros1-bz2.bag     the same, bz2 chunks
    ros1-png      ros1-png.bag     Imu + CompressedImage (png) on <camera topic>/compressed
    ros2-mcap     ros2-mcap/       rosbag2 folder: metadata.yaml, ros2-mcap_0.mcap (zstd chunks)
    single        single.mcap      the same MCAP alone, zstd chunks
    single-lz4    single-lz4.mcap  lz4 chunks
    single-none   single-none.mcap uncompressed chunks
    ros2-sqlite   ros2-sqlite/     rosbag2 folder: metadata.yaml, ros2-sqlite_0.db3
    ros2-png      ros2-png.mcap    Imu + CompressedImage (png) on <camera topic>/compressed
and write_bags.yaml, what read_back.py needs to check them (the recording's path, the outputs).

Every output holds the same messages in the same order (by time, the IMU's first at equal
times), stamped and logged at the recording's timestamps. Needs Debian's python3-rosbag,
python3-sensor-msgs, python3-zstandard, python3-lz4, python3-yaml and python3-opencv (PNG)."""
import argparse
import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import yaml

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import recording as recording_io  # noqa: E402
import ros1_bags  # noqa: E402
import ros2_bags  # noqa: E402
import ros2_msgs  # noqa: E402

# name -> (path in OUT_DIR, kind, options). bz2 first: by far the slowest (Python's bz2 at
# ~7 MB/s), it runs beside the others.
OUTPUTS = {
    'ros1-bz2': ('ros1-bz2.bag', 'ros1', dict(compression='bz2')),
    'ros1': ('ros1.bag', 'ros1', dict(compression='none')),
    'ros1-lz4': ('ros1-lz4.bag', 'ros1', dict(compression='lz4')),
    'ros1-png': ('ros1-png.bag', 'ros1', dict(compression='none', png_images=True)),
    'ros2-mcap': ('ros2-mcap', 'mcap-bag', dict(compression='zstd')),
    'single': ('single.mcap', 'mcap', dict(compression='zstd')),
    'single-lz4': ('single-lz4.mcap', 'mcap', dict(compression='lz4')),
    'single-none': ('single-none.mcap', 'mcap', dict(compression='')),
    'ros2-sqlite': ('ros2-sqlite', 'sqlite-bag', dict()),
    'ros2-png': ('ros2-png.mcap', 'mcap', dict(compression='zstd', png_images=True)),
}
MANIFEST = 'write_bags.yaml'


def write_output(name, rec, ros2, out_dir):
    """Writes one output; ros2 maps png_images (False/True) to ros2_msgs.serialize's result."""
    path, kind, options = OUTPUTS[name]
    options = dict(options)
    target = os.path.join(out_dir, path)
    if kind == 'ros1':
        ros1_bags.write_bag(target, rec, **options)
        return
    topics, messages = ros2[options.pop('png_images', False)]
    if kind == 'mcap':
        ros2_bags.write_mcap(target, topics, messages, **options)
    elif kind == 'mcap-bag':
        ros2_bags.write_mcap_bag(target, topics, messages, **options)
    else:
        ros2_bags.write_sqlite_bag(target, topics, messages)


def write_manifest(out_dir, rec, names):
    manifest = {'recording': rec.path, 'imu_topic': rec.imu_topic,
                'camera_topic': rec.camera_topic, 'imu_samples': len(rec.imu),
                'frames': len(rec.frames), 'outputs': {n: OUTPUTS[n][0] for n in names}}
    with open(os.path.join(out_dir, MANIFEST), 'w', encoding='utf-8') as f:
        yaml.safe_dump(manifest, f, sort_keys=False)


def size_of(path):
    if os.path.isdir(path):
        return sum(os.path.getsize(os.path.join(path, n)) for n in os.listdir(path))
    return os.path.getsize(path)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('recording')
    parser.add_argument('out_dir')
    parser.add_argument('--only', nargs='+', choices=list(OUTPUTS), metavar='NAME',
                        help='write only these outputs: ' + ', '.join(OUTPUTS))
    parser.add_argument('--jobs', type=int, default=os.cpu_count() or 1,
                        help='outputs written at once (threads; the compressors release the '
                             'GIL); default: the cores')
    args = parser.parse_args(argv)
    names = [n for n in OUTPUTS if not args.only or n in args.only]

    started = time.monotonic()
    rec = recording_io.load(args.recording)
    os.makedirs(args.out_dir, exist_ok=True)
    # The CDR of every message, made once for all the ROS 2 outputs that need it.
    kinds = {OUTPUTS[n][2].get('png_images', False) for n in names if OUTPUTS[n][1] != 'ros1'}
    ros2 = {png: ros2_msgs.serialize(rec, png_images=png) for png in kinds}
    print(f'read {len(rec.imu)} IMU samples, {len(rec.frames)} frames '
          f'({rec.imu_topic}, {rec.camera_topic}) in {time.monotonic() - started:.1f} s')

    def timed(name):
        t0 = time.monotonic()
        write_output(name, rec, ros2, args.out_dir)
        return time.monotonic() - t0

    with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        seconds = dict(zip(names, pool.map(timed, names)))
    for name in names:
        path = os.path.join(args.out_dir, OUTPUTS[name][0])
        print(f'{OUTPUTS[name][0]:18} {size_of(path):>12,} bytes  {seconds[name]:5.1f} s')
    write_manifest(args.out_dir, rec, names)
    print(f'wrote {len(names)} outputs in {time.monotonic() - started:.1f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
