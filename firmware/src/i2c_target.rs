//! Emulated I²C targets: a device's registers as its I²C interface presents them
//! ([`Target`]), and a bus of one such target ([`TargetBus`]) that implements
//! [`embedded_hal_async::i2c::I2c`], so a driver runs unchanged against it. The emulated
//! board's accelerometer is the ADXL355 driver on a bus of the register model
//! ([`crate::adxl355::model`]); the drivers' host tests record what goes over such a bus
//! (`fakes::RecordingBus`).

use embedded_hal_async::i2c::{ErrorKind, ErrorType, I2c, NoAcknowledgeSource, Operation};

/// A device on the bus as its I²C interface presents it: a register pointer set by the
/// first byte of a write, data bytes written and read from the pointer on.
pub trait Target {
    /// The 7-bit address it answers.
    fn address(&self) -> u8;
    /// One write: the register pointer, then the data bytes (if any).
    fn write(&mut self, bytes: &[u8]) -> Result<(), ErrorKind>;
    /// One read from the register pointer into `buf`.
    fn read(&mut self, buf: &mut [u8]) -> Result<(), ErrorKind>;
}

/// A bus with one target, or none (then nothing acknowledges: an unfitted part).
pub struct TargetBus<T> {
    /// The device on the bus.
    pub target: Option<T>,
}

impl<T> TargetBus<T> {
    /// A bus with `target` on it (`None`: an empty bus).
    pub const fn new(target: Option<T>) -> Self {
        TargetBus { target }
    }
}

impl<T> ErrorType for TargetBus<T> {
    type Error = ErrorKind;
}

impl<T: Target> I2c for TargetBus<T> {
    async fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), ErrorKind> {
        let target = self
            .target
            .as_mut()
            .filter(|t| t.address() == address)
            .ok_or(ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address))?;
        for op in operations {
            match op {
                Operation::Write(bytes) => target.write(bytes)?,
                Operation::Read(buf) => target.read(buf)?,
            }
        }
        Ok(())
    }
}
