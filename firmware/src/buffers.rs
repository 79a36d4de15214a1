//! The firmware's static buffers: stored frames, the protocol's receive buffer and the
//! pipeline's working memory (the laser-off frame that becomes the difference frame, the run
//! tables, the per-point buffers, the object features, the read-out extraction's tables), declared for every board by one
//! macro, [`board_buffers!`], in the RAM regions the board chooses.

/// A frame buffer, aligned for DMA (32 bytes: a word for the DCMI's word transfers, a cache
/// line of the Cortex-M7).
#[cfg_attr(not(any(test, feature = "h743", feature = "qemu")), allow(dead_code))]
#[repr(C, align(32))]
pub struct FrameBuffer<const N: usize>(pub [u8; N]);

/// Defines `take_buffers(pixels)`, which hands out the board's buffers once (`None`
/// afterwards): the application's [`crate::app::Buffers`] (a stored laser-off frame of
/// `off_bytes` and laser-on frame of `on_bytes` — for raw captures and cameras that do not
/// stream; either may be 0 — and the protocol receive buffer) and the pipeline's
/// [`tangent_core::pipeline::Workspace`] for frames of `pixels` pixels (at most
/// `diff_bytes`: the laser-off frame the streamed subtraction turns into the difference) and
/// `points` curve points. Each buffer is a static, with the attributes given before its name
/// (e.g. the link section of a RAM region).
///
/// ```ignore
/// crate::buffers::board_buffers! {
///     off_bytes = 0, on_bytes = WINDOW_BYTES, diff_bytes = FRAME_BYTES, points = POINTS;
///     #[link_section = ".axisram"] off;
///     #[link_section = ".axisram"] on;
///     #[link_section = ".axisram"] diff;
///     #[link_section = ".sram123"] runs;
///     #[link_section = ".sram123"] small;
///     objects;
///     #[link_section = ".sram4"] readout;
///     #[link_section = ".axisram"] faint;
/// }
/// ```
#[cfg_attr(
    not(any(test, feature = "h743", feature = "qemu")),
    allow(unused_macros)
)]
macro_rules! board_buffers {
    (
        off_bytes = $off_bytes:expr, on_bytes = $on_bytes:expr, diff_bytes = $diff_bytes:expr,
        points = $points:expr;
        $(#[$off:meta])* off;
        $(#[$on:meta])* on;
        $(#[$diff:meta])* diff;
        $(#[$runs:meta])* runs;
        $(#[$small:meta])* small;
        $(#[$objects:meta])* objects;
        $(#[$readout:meta])* readout;
        $(#[$faint:meta])* faint;
    ) => {
        /// The board's buffers, once: the application's frames and receive buffer, and the
        /// pipeline's workspace for frames of `pixels` pixels (at most the board's frame).
        pub fn take_buffers(
            pixels: usize,
        ) -> Option<(
            $crate::app::Buffers<'static>,
            tangent_core::pipeline::Workspace<'static, u8>,
        )> {
            use core::ptr::{addr_of_mut, write_bytes};
            use core::sync::atomic::{AtomicBool, Ordering};
            use tangent_core::protocol::MAX_FRAME_LEN;
            use $crate::buffers::FrameBuffer;
            use tangent_core::pipeline::{
                FaintBuffers, Objects, ReadoutBuffers, RunBuffers, SmallBuffers, Workspace,
                NO_OBJECTS,
            };

            const OFF_BYTES: usize = $off_bytes;
            const ON_BYTES: usize = $on_bytes;
            const DIFF_BYTES: usize = $diff_bytes;
            static TAKEN: AtomicBool = AtomicBool::new(false);
            $(#[$off])*
            static mut OFF: FrameBuffer<OFF_BYTES> = FrameBuffer([0; OFF_BYTES]);
            $(#[$on])*
            static mut ON: FrameBuffer<ON_BYTES> = FrameBuffer([0; ON_BYTES]);
            $(#[$diff])*
            static mut DIFF: FrameBuffer<DIFF_BYTES> = FrameBuffer([0; DIFF_BYTES]);
            $(#[$runs])*
            static mut RUNS: RunBuffers = RunBuffers::new();
            $(#[$small])*
            static mut SMALL: SmallBuffers<{ $points }> = SmallBuffers::new();
            $(#[$objects])*
            static mut OBJECTS: Objects = NO_OBJECTS;
            $(#[$readout])*
            static mut READOUT: ReadoutBuffers = ReadoutBuffers::new();
            $(#[$faint])*
            static mut FAINT: FaintBuffers = FaintBuffers::new();
            static mut RX: [u8; MAX_FRAME_LEN] = [0; MAX_FRAME_LEN];

            if TAKEN.swap(true, Ordering::AcqRel) {
                return None;
            }
            let pixels = pixels.min(DIFF_BYTES);
            // SAFETY: `TAKEN` lets this point be reached once, so these are the only
            // references to the statics, for the program's life. A board may place them in
            // NOLOAD sections (not initialised at reset): they are zeroed in place (all-zero
            // bytes are a valid value of every buffer type) rather than built on the stack.
            unsafe {
                write_bytes(addr_of_mut!(OFF), 0, 1);
                write_bytes(addr_of_mut!(ON), 0, 1);
                write_bytes(addr_of_mut!(DIFF), 0, 1);
                write_bytes(addr_of_mut!(RUNS), 0, 1);
                write_bytes(addr_of_mut!(SMALL), 0, 1);
                write_bytes(addr_of_mut!(OBJECTS), 0, 1);
                write_bytes(addr_of_mut!(READOUT), 0, 1);
                write_bytes(addr_of_mut!(FAINT), 0, 1);
                let buffers = $crate::app::Buffers {
                    off: &mut (*addr_of_mut!(OFF)).0,
                    on: &mut (*addr_of_mut!(ON)).0,
                    rx: &mut *addr_of_mut!(RX),
                };
                let diff = &mut (*addr_of_mut!(DIFF)).0;
                let workspace = Workspace::from_parts(
                    &mut diff[..pixels],
                    &mut *addr_of_mut!(OBJECTS),
                    &mut *addr_of_mut!(RUNS),
                    &mut *addr_of_mut!(SMALL),
                    &mut *addr_of_mut!(READOUT),
                    &mut *addr_of_mut!(FAINT),
                );
                Some((buffers, workspace))
            }
        }
    };
}
#[cfg_attr(
    not(any(test, feature = "h743", feature = "qemu")),
    allow(unused_imports)
)]
pub(crate) use board_buffers;

#[cfg(test)]
mod tests {
    mod board {
        crate::buffers::board_buffers! {
            off_bytes = 64, on_bytes = 0, diff_bytes = 64, points = 8;
            off;
            on;
            diff;
            runs;
            small;
            objects;
            readout;
            faint;
        }
    }

    #[test]
    fn buffers_are_handed_out_once() {
        let (buffers, workspace) = board::take_buffers(48).expect("the first time");
        assert_eq!((buffers.off.len(), buffers.on.len()), (64, 0));
        assert_eq!(buffers.off.as_ptr() as usize % 32, 0, "aligned for DMA");
        assert_eq!(workspace.diff.as_ptr() as usize % 32, 0, "aligned for DMA");
        assert_eq!(buffers.rx.len(), tangent_core::protocol::MAX_FRAME_LEN);
        assert_eq!(workspace.diff.len(), 48);
        assert!(!workspace.runs.is_empty() && !workspace.candidate_runs.is_empty());
        assert_eq!(workspace.curve.len(), 8);
        assert!(board::take_buffers(48).is_none(), "the second time");
    }
}
