#!/usr/bin/python3
# Writes a ROS 1 bag with Debian's python3-rosbag (an independent writer) for
# tests/formats/rosbag1_test.cc: write_rosbag1.py OUT.bag none|bz2|lz4 N.
# Sample i (i = 0..N-1), record time 1000 s + i ms:
#   /imu      sensor_msgs/Imu, stamp 100 s + i*5 ms + 7 ns, accel (0.1 i, -9.81 + 0.001 i, 0.5),
#             gyro (0.01 i, -0.02 i, 0.003)
#   /mag      sensor_msgs/MagneticField, stamp 0 (unset: record time), field (2e-5 + 1e-9 i,
#             -3e-6, 4.5e-5) T
#   /temp     sensor_msgs/Temperature, stamp 100 s + i*5 ms, 25 + 0.01 i degC
#   /chatter  std_msgs/String (skipped by the reader)
import sys

import rosbag
import rospy
from sensor_msgs.msg import Imu, MagneticField, Temperature
from std_msgs.msg import String

out, compression, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
with rosbag.Bag(out, "w", compression=compression, chunk_threshold=4096) as bag:
    for i in range(n):
        rec = rospy.Time(1000, i * 1000000)
        imu = Imu()
        imu.header.stamp = rospy.Time(100, i * 5000000 + 7)
        imu.header.frame_id = "imu_link"
        imu.linear_acceleration.x = 0.1 * i
        imu.linear_acceleration.y = -9.81 + 0.001 * i
        imu.linear_acceleration.z = 0.5
        imu.angular_velocity.x = 0.01 * i
        imu.angular_velocity.y = -0.02 * i
        imu.angular_velocity.z = 0.003
        imu.orientation_covariance[0] = -1
        bag.write("/imu", imu, rec)
        mag = MagneticField()
        mag.magnetic_field.x = 2e-5 + 1e-9 * i
        mag.magnetic_field.y = -3e-6
        mag.magnetic_field.z = 4.5e-5
        bag.write("/mag", mag, rec)
        temp = Temperature()
        temp.header.stamp = rospy.Time(100, i * 5000000)
        temp.temperature = 25 + 0.01 * i
        bag.write("/temp", temp, rec)
        bag.write("/chatter", String(data="hello %d" % i), rec)
