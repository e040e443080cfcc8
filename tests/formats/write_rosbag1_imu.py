#!/usr/bin/python3
# Writes the samples of one IMU as a ROS 1 bag with Debian's python3-rosbag (an independent
# writer) for the upload tests (tests/server/bag_upload_test.cc):
#   write_rosbag1_imu.py OUT.bag none|bz2|lz4 SAMPLES.txt
# SAMPLES.txt: one line per sample, "record_ns stamp_sec stamp_nsec ax ay az gx gy gz" (SI; the
# values as %.17g, so that they round-trip exactly), written to /imu as sensor_msgs/Imu with that
# header stamp and record time.
import sys

import rosbag
import rospy
from sensor_msgs.msg import Imu

out, compression, samples = sys.argv[1], sys.argv[2], sys.argv[3]
with rosbag.Bag(out, "w", compression=compression) as bag, open(samples) as lines:
    for line in lines:
        f = line.split()
        record_ns, sec, nsec = int(f[0]), int(f[1]), int(f[2])
        imu = Imu()
        imu.header.stamp = rospy.Time(sec, nsec)
        imu.header.frame_id = "imu_link"
        imu.linear_acceleration.x, imu.linear_acceleration.y, imu.linear_acceleration.z = (
            float(f[3]), float(f[4]), float(f[5]))
        imu.angular_velocity.x, imu.angular_velocity.y, imu.angular_velocity.z = (
            float(f[6]), float(f[7]), float(f[8]))
        imu.orientation_covariance[0] = -1
        bag.write("/imu", imu, rospy.Time(record_ns // 10**9, record_ns % 10**9))
