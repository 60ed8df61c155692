// The IMU a device specification names, opened and configured: spi -> ICM-42688-P, i2c ->
// MPU-6050, can -> Bosch MM7.10. Throws DriverError with a message naming the device.
#pragma once

#include <memory>

#include "mirrorcal/drivers/device_spec.hpp"
#include "mirrorcal/drivers/register_imu.hpp"
#include "mirrorcal/hal/lines.hpp"
#include "mirrorcal/hal/sources.hpp"

namespace mirrorcal::drivers {

// drdy (may be null; not owned) paces the register IMUs; a CAN IMU takes none.
std::unique_ptr<hal::ImuSource> open_imu(const ImuSpec& spec, const RegisterImuConfig& config,
                                         hal::DataReadyLine* drdy);

}  // namespace mirrorcal::drivers
