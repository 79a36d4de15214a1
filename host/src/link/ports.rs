//! Finding a Tangent among the system's serial ports (USB VID/PID, serial number).

use tangent_core::protocol::codes;

use super::DeviceIdentity;

/// A serial port that may be a Tangent.
#[derive(Debug, Clone, PartialEq)]
pub struct PortCandidate {
    /// Path to open.
    pub path: String,
    /// USB vendor/product id, when it is a USB port.
    pub usb: Option<(u16, u16)>,
    /// USB serial number (the device id in the field log), when known.
    pub serial_number: Option<String>,
    /// USB product string.
    pub product: Option<String>,
    /// Whether the VID/PID is the Tangent's.
    pub is_tangent: bool,
}

/// Every serial port the system knows, Tangents (by USB VID/PID) first.
pub fn list_ports() -> Result<Vec<PortCandidate>, serialport::Error> {
    let mut out: Vec<PortCandidate> = serialport::available_ports()?
        .into_iter()
        .map(|p| {
            let (usb, serial_number, product) = match p.port_type {
                serialport::SerialPortType::UsbPort(u) => {
                    (Some((u.vid, u.pid)), u.serial_number, u.product)
                }
                _ => (None, None, None),
            };
            PortCandidate {
                is_tangent: usb == Some((codes::USB_VID, codes::USB_PID)),
                path: p.port_name,
                usb,
                serial_number,
                product,
            }
        })
        .collect();
    out.sort_by(|a, b| b.is_tangent.cmp(&a.is_tangent).then(a.path.cmp(&b.path)));
    Ok(out)
}

/// The USB serial number of the port at `path`, if the system knows one.
pub fn usb_serial_number(path: &str) -> Option<String> {
    let canonical = std::fs::canonicalize(path).ok();
    list_ports().ok()?.into_iter().find_map(|p| {
        let same = p.path == path || std::fs::canonicalize(&p.path).ok() == canonical;
        if same {
            p.serial_number
        } else {
            None
        }
    })
}

/// A stable id for the device in the field log: its USB serial number, else the board.
pub fn device_id(path: &str, identity: &DeviceIdentity) -> String {
    usb_serial_number(path)
        .unwrap_or_else(|| tangent_field::record::board_device_id(identity.board).to_string())
}
