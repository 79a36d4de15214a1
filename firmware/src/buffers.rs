//! The firmware's static buffers: frames, the protocol's receive buffer and the pipeline's
//! working memory, declared for every board by one macro, [`board_buffers!`], in the RAM
//! regions the board chooses.

/// A frame buffer, aligned for DMA (32 bytes: a word for the DCMI's word transfers, a cache
/// line of the Cortex-M7).
#[cfg_attr(not(any(test, feature = "h743", feature = "qemu")), allow(dead_code))]
#[repr(C, align(32))]
pub struct FrameBuffer<const N: usize>(pub [u8; N]);

/// Defines `take_buffers(pixels)`, which hands out the board's buffers once (`None`
/// afterwards): the application's [`crate::app::Buffers`] (two frames of `frame_bytes` bytes
/// and the protocol receive buffer) and the pipeline's [`tangent_core::pipeline::Workspace`]
/// for `pixels` pixels (at most `frame_bytes`) and `points` curve points. Each buffer is a
/// static, with the attributes given before its name (e.g. the link section of a RAM region).
///
/// ```ignore
/// crate::buffers::board_buffers! {
///     frame_bytes = FRAME_BYTES, points = POINTS;
///     #[link_section = ".axisram"] frames;
///     #[link_section = ".axisram"] diff;
///     #[link_section = ".sram123"] labels;
///     #[link_section = ".axisram"] small;
///     objects;
/// }
/// ```
#[cfg_attr(
    not(any(test, feature = "h743", feature = "qemu")),
    allow(unused_macros)
)]
macro_rules! board_buffers {
    (
        frame_bytes = $frame_bytes:expr, points = $points:expr;
        $(#[$frames:meta])* frames;
        $(#[$diff:meta])* diff;
        $(#[$labels:meta])* labels;
        $(#[$small:meta])* small;
        $(#[$objects:meta])* objects;
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
            use tangent_core::pipeline::{Objects, SmallBuffers, Workspace, NO_OBJECTS};

            // (Not `FRAME_BYTES`: the caller's constant may have that name.)
            const BYTES: usize = $frame_bytes;
            static TAKEN: AtomicBool = AtomicBool::new(false);
            $(#[$frames])*
            static mut FRAMES: [FrameBuffer<BYTES>; 2] =
                [FrameBuffer([0; BYTES]), FrameBuffer([0; BYTES])];
            $(#[$diff])*
            static mut DIFF: [u8; BYTES] = [0; BYTES];
            $(#[$labels])*
            static mut LABELS: [u16; BYTES] = [0; BYTES];
            $(#[$small])*
            static mut SMALL: SmallBuffers<{ $points }> = SmallBuffers::new();
            $(#[$objects])*
            static mut OBJECTS: Objects = NO_OBJECTS;
            static mut RX: [u8; MAX_FRAME_LEN] = [0; MAX_FRAME_LEN];

            if TAKEN.swap(true, Ordering::AcqRel) {
                return None;
            }
            let pixels = pixels.min(BYTES);
            // SAFETY: `TAKEN` lets this point be reached once, so these are the only
            // references to the statics, for the program's life. A board may place them in
            // NOLOAD sections (not initialised at reset): they are zeroed in place (all-zero
            // bytes are a valid value of every buffer type) rather than built on the stack.
            unsafe {
                write_bytes(addr_of_mut!(FRAMES), 0, 1);
                write_bytes(addr_of_mut!(DIFF), 0, 1);
                write_bytes(addr_of_mut!(LABELS), 0, 1);
                write_bytes(addr_of_mut!(SMALL), 0, 1);
                write_bytes(addr_of_mut!(OBJECTS), 0, 1);
                let [off, on] = &mut *addr_of_mut!(FRAMES);
                let buffers = $crate::app::Buffers {
                    off: &mut off.0,
                    on: &mut on.0,
                    rx: &mut *addr_of_mut!(RX),
                };
                let diff = &mut *addr_of_mut!(DIFF);
                let labels = &mut *addr_of_mut!(LABELS);
                let workspace = Workspace::from_parts(
                    &mut diff[..pixels],
                    &mut labels[..pixels],
                    &mut *addr_of_mut!(OBJECTS),
                    &mut *addr_of_mut!(SMALL),
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
            frame_bytes = 64, points = 8;
            frames;
            diff;
            labels;
            small;
            objects;
        }
    }

    #[test]
    fn buffers_are_handed_out_once() {
        let (buffers, workspace) = board::take_buffers(48).expect("the first time");
        assert_eq!((buffers.off.len(), buffers.on.len()), (64, 64));
        assert_eq!(buffers.off.as_ptr() as usize % 32, 0, "aligned for DMA");
        assert_eq!(buffers.rx.len(), tangent_core::protocol::MAX_FRAME_LEN);
        assert_eq!((workspace.diff.len(), workspace.labels.len()), (48, 48));
        assert_eq!(workspace.curve.len(), 8);
        assert!(board::take_buffers(48).is_none(), "the second time");
    }
}
