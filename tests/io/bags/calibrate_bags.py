#!/usr/bin/python3
"""`mirrorcal calibrate` on bags written by the formats' own writers (write_bags.py, checked by
read_back.py), and on the ROS 2 bag `mirrorcal record --bag` writes (checked by read_back.py's
readers too): every bag of a recording calibrates to the bytes of its folder's calibration from
the same images, and a bag that is cut off, damaged, missing its topic or its sensor files is
refused with a message naming the file, the topic and the place.

    calibrate_bags.py MIRRORCAL WORK_DIR

WORK_DIR is emptied first and removed when every check passes."""
import os
import shutil
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import mcap_reader  # noqa: E402
import read_back  # noqa: E402
import recording as recording_io  # noqa: E402

SENSOR_FILES = ('imu.yaml', 'camchain.yaml', 'mirrorcal.yaml', 'truth.yaml')
# The folder's result names the fingerprint of its CSV files, a bag's that of its messages.
DIFFERS_BY_SOURCE = ('recording_fingerprint:',)
failures = []


def run(mirrorcal, *args):
    p = subprocess.run([mirrorcal, *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                       text=True)
    return p.returncode, p.stdout


def check(ok, what):
    print(('ok: ' if ok else 'FAILED: ') + what)
    if not ok:
        failures.append(what)


def result_lines(out_dir, name):
    with open(os.path.join(out_dir, name)) as f:
        return [line for line in f if not line.startswith(DIFFERS_BY_SOURCE)]


def calibrates_as_folder(mirrorcal, bag, reference, out_dir, *options):
    code, output = run(mirrorcal, 'calibrate', bag, '--out', out_dir, *options)
    if code != reference[0]:
        check(False, f'{bag}: exit status {code}, the folder\'s {reference[0]}:\n{output}')
        return
    same = all(result_lines(out_dir, f) == result_lines(reference[1], f)
               for f in ('mirrorcal-result.yaml', 'camchain-imucam.yaml', 'estimates.csv'))
    check(same, f'{bag} calibrates to the bytes of its folder\'s calibration')


def refused(mirrorcal, bag, expected, *options):
    code, output = run(mirrorcal, 'calibrate', bag, '--out', bag + '-out', *options)
    missing = [e for e in expected if e not in output]
    check(code != 0 and not missing,
          f'{os.path.basename(bag)} {" ".join(options)} is refused naming {expected}' +
          ('' if code != 0 and not missing else f' (exit {code}; missing {missing}):\n{output}'))


def cut_copy(src, dst, keep):
    with open(src, 'rb') as f:
        data = f.read()
    with open(dst, 'wb') as f:
        f.write(keep(data))


def main(mirrorcal, work):
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    rec, bags = os.path.join(work, 'rec'), os.path.join(work, 'bags')
    code, output = run(mirrorcal, 'record', '--seed', '4', '--images', '--duration', '4', '--out',
                       rec)
    if code != 0:
        sys.exit('record failed:\n' + output)
    subprocess.run(['/usr/bin/python3', os.path.join(HERE, 'write_bags.py'), rec, bags],
                   check=True)
    # The writers checked first: python3-rosbag's reader and read_back's own MCAP reader find
    # the recording in every bag, sample for sample and pixel for pixel.
    subprocess.run(['/usr/bin/python3', os.path.join(HERE, 'read_back.py'), bags], check=True)
    # The sensor files beside the bags: where calibrate looks when not told (--sensors).
    for f in SENSOR_FILES:
        shutil.copy(os.path.join(rec, f), bags)

    folder_out = os.path.join(work, 'out-folder')
    code, output = run(mirrorcal, 'calibrate', rec, '--from-images', '--out', folder_out)
    print(output.splitlines()[-1] if output else '')
    reference = (code, folder_out)
    for name in sorted(os.listdir(bags)):
        if name.endswith(('.bag', '.mcap')) or os.path.isdir(os.path.join(bags, name)):
            calibrates_as_folder(mirrorcal, os.path.join(bags, name), reference,
                                 os.path.join(work, 'out-' + name))
    calibrates_as_folder(mirrorcal, os.path.join(bags, 'ros1.bag'), reference,
                         os.path.join(work, 'out-sensors'), '--sensors', rec)

    # record --bag: the same recording as a ROS 2 bag of mirrorcal's own writing, read back by
    # read_back's MCAP reader (records, CRCs, indexes, summary, rosbag2's metadata) message for
    # message against the folder's images, and calibrated as a folder and as its single file.
    recbag = os.path.join(work, 'recbag')
    code, output = run(mirrorcal, 'record', '--seed', '4', '--bag', '--duration', '4', '--out',
                       recbag)
    check(code == 0, 'record --bag exits 0' + ('' if code == 0 else ':\n' + output))
    try:
        expected = read_back.Expected(recording_io.load(rec), png_images=False)
        held = read_back.check_bag_folder(recbag, expected, 'mcap', '.mcap', read_back.check_mcap,
                                          'zstd')
        check(True, 'record --bag is a ROS 2 bag of the recording: ' + held)
    except (read_back.Mismatch, mcap_reader.McapError, OSError) as e:
        check(False, f'record --bag is a ROS 2 bag of the recording: {e}')
    calibrates_as_folder(mirrorcal, recbag, reference, os.path.join(work, 'out-recbag'))
    calibrates_as_folder(mirrorcal, os.path.join(recbag, 'recbag_0.mcap'), reference,
                         os.path.join(work, 'out-recbag-file'))

    # Bad input: each refused with the file, the topic or the place named.
    bad = os.path.join(work, 'bad')
    os.makedirs(bad)
    for f in SENSOR_FILES:
        shutil.copy(os.path.join(rec, f), bad)
    ros1 = os.path.join(bags, 'ros1.bag')
    half = os.path.join(bad, 'half.bag')
    cut_copy(ros1, half, lambda d: d[:len(d) // 2])
    refused(mirrorcal, half, [half, 'cut off', 'at byte'])
    refused(mirrorcal, ros1, [ros1, 'no topic /nowhere', '/imu0 (sensor_msgs/Imu'],
            '--imu-topic', '/nowhere')
    refused(mirrorcal, ros1, ['topic /cam0/image_raw carries sensor_msgs/Image, not sensor_msgs/Imu'],
            '--imu-topic', '/cam0/image_raw')
    mcap = os.path.join(bags, 'single-none.mcap')
    cut = os.path.join(bad, 'cut.mcap')
    cut_copy(mcap, cut, lambda d: d[:len(d) * 2 // 3])
    refused(mirrorcal, cut, [cut, 'cut off'])
    damaged = os.path.join(bad, 'damaged.mcap')
    cut_copy(mcap, damaged,
             lambda d: d[:len(d) // 2] + bytes([d[len(d) // 2] ^ 0xff]) + d[len(d) // 2 + 1:])
    refused(mirrorcal, damaged, [damaged, 'topic /imu0', 'at byte', 'CRC'])
    lonely = os.path.join(work, 'lonely')
    os.makedirs(lonely)
    os.link(mcap, os.path.join(lonely, 'single.mcap'))
    refused(mirrorcal, os.path.join(lonely, 'single.mcap'), [os.path.join(lonely, 'imu.yaml')])

    if failures:
        sys.exit(f'{len(failures)} checks failed')
    shutil.rmtree(work)
    print('calibrate_bags: every bag calibrates as its folder; bad bags are refused clearly')


if __name__ == '__main__':
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
