// ROS 2 messages in CDR (the DDS serialization: rosbag2's .db3 and MCAP's "cdr" encoding) for
// the sensor messages calibd reads (formats/ros_topics.h).
#ifndef CALIBD_FORMATS_CDR_H_
#define CALIBD_FORMATS_CDR_H_

#include <string_view>

#include "formats/ros_topics.h"

namespace calibd::server {

// The type read for a ROS 2 type name ("sensor_msgs/msg/Imu", ...); kOther for every other.
RosMessageType Ros2MessageType(std::string_view type_name);

// Decodes one CDR message of `type` (4-byte encapsulation header, little- or big-endian plain
// CDR, fields aligned to their size from the end of that header) into s->stamp_ns and the values;
// false when it is too short or its encapsulation is not plain CDR. Stateless, thread-safe.
bool DecodeCdrMessage(std::string_view data, RosMessageType type, RosSample* s);

}  // namespace calibd::server

#endif  // CALIBD_FORMATS_CDR_H_
