//! The emulated device: the QEMU command line that runs the firmware's `qemu` board
//! (`mps2-an500`, Cortex-M7, semihosting), shared by the tests, the instruction-count
//! benchmark and `firmware/qemu/run.sh` (which spells the same flags for people).

use std::path::Path;
use std::process::Command;

/// `qemu-system-arm` running the emulated firmware `elf`, its UART on `serial` (QEMU
/// `-serial` syntax: `stdio`, `pty`, `null`, …), with the firmware's command line `append`
/// (frame files, `--calib FILE`, `--bench`). With `icount`, QEMU advances its virtual clock one
/// nanosecond per instruction, which turns the firmware's SysTick clock into an instruction
/// counter (docs/performance.md). The firmware's semihosting log goes to QEMU's stderr.
pub fn qemu_command(elf: &Path, serial: &str, icount: bool, append: &str) -> Command {
    let mut cmd = Command::new("qemu-system-arm");
    cmd.args([
        "-M",
        "mps2-an500",
        "-display",
        "none",
        "-monitor",
        "none",
        "-nodefaults",
        "-net",
        "none",
    ]);
    if icount {
        cmd.args(["-icount", "shift=0"]);
    }
    cmd.args(["-serial", serial])
        .args(["-semihosting-config", "enable=on,target=native"])
        .arg("-kernel")
        .arg(elf)
        .arg("-append")
        .arg(append);
    cmd
}
