// All probeless message types (see docs/messages.md).
#pragma once

#include "probeless/msgs/auxiliary_views.h"
#include "probeless/msgs/camera_info.h"
#include "probeless/msgs/face_observation.h"
#include "probeless/msgs/geometry.h"
#include "probeless/msgs/geometry_buffer.h"
#include "probeless/msgs/header.h"
#include "probeless/msgs/image.h"
#include "probeless/msgs/layout.h"
#include "probeless/msgs/pose.h"
#include "probeless/msgs/replay.h"
#include "probeless/msgs/sh_light.h"
#include "probeless/msgs/tracking_status.h"
#include "probeless/msgs/transfer_buffer.h"
