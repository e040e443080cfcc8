// Forwarding header: Status lives in the base library (base/status.h), shared by every layer.
#ifndef CALIBD_CORE_STATUS_H_
#define CALIBD_CORE_STATUS_H_

#include "base/status.h"

#endif  // CALIBD_CORE_STATUS_H_
