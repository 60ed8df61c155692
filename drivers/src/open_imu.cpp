#include "mirrorcal/drivers/open_imu.hpp"

#include "mirrorcal/drivers/can_imu.hpp"

namespace mirrorcal::drivers {

std::unique_ptr<hal::ImuSource> open_imu(const ImuSpec& spec, const RegisterImuConfig& config,
                                         hal::DataReadyLine* drdy) {
  switch (spec.bus) {
    case ImuBus::kSpi: {
      // The ICM-42688-P: SPI mode 0 or 3, up to 24 MHz; 8 MHz leaves margin on board wiring.
      auto transport = std::make_unique<SpidevTransport>(spec.device, 8'000'000, 0);
      return std::make_unique<Icm42688>(std::make_unique<SpiRegisterBus>(std::move(transport)),
                                        config, drdy);
    }
    case ImuBus::kI2c:
      return std::make_unique<Mpu6050>(std::make_unique<I2cBus>(spec.device, spec.i2c_address),
                                       config, drdy);
    case ImuBus::kCan:
      if (drdy != nullptr)
        throw DriverError(Fault::kBadSpec, spec.text +
                                               ": a CAN IMU has no data-ready line "
                                               "(its frames carry their own timing)");
      return std::make_unique<CanImu>(open_mm710_socket(spec.device), spec.device);
  }
  throw DriverError(Fault::kBadSpec, spec.text + ": unknown bus");
}

}  // namespace mirrorcal::drivers
