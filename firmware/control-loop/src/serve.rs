//! One session of the control loop: bytes in from the board's link, frames out, until the host says
//! `Shutdown`. The receive buffer is `shared_types::protocol::Reader` and the reply buffer one
//! `MAX_FRAME` array, both on the stack of [`serve`]; nothing else is buffered.

use crate::app::{Action, App, Stats};
use crate::board::{Link, Meter};
use shared_types::protocol::{encode_frame, Reader, MAX_FRAME};

/// How a session ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum End {
    /// The host sent `Shutdown`; the session's counters.
    Shutdown(Stats),
    /// A reply did not fit `MAX_FRAME`. `MAX_FRAME` is sized for the largest reply, so this is a bug; the
    /// board says so and stops as it stops on a panic (without one: no panicking path may remain).
    ReplyTooLarge,
}

/// Serves frames from `link` until the host sends `Shutdown`: every complete frame goes to
/// [`App::on_frame`] (which measures the evaluation with `meter`) and its reply is sent back at once.
pub fn serve<L: Link, M: Meter>(app: &mut App<'_>, link: &mut L, meter: &mut M) -> End {
    let mut reader = Reader::new();
    let mut out = [0u8; MAX_FRAME];
    loop {
        let byte = link.read_byte();
        let Some(ev) = reader.push(byte) else {
            continue;
        };
        match app.on_frame(ev, meter) {
            Action::Reply(reply) => match encode_frame(&reply, &mut out) {
                Ok(frame) => link.write_all(frame),
                Err(_) => return End::ReplyTooLarge,
            },
            Action::Shutdown => return End::Shutdown(app.stats()),
        }
    }
}

#[cfg(test)]
mod tests {
    //! The loop against a mock board: the link is a queue of bytes in and a buffer of bytes out, the
    //! meter counts its calls. The image is the one `build.rs` embeds (the default test image unless
    //! `CONTROLLER_IMAGE` is set: the double integrator, `u = K x` with `K = [-4, -3.8]` inside the ball
    //! of radius 10 around the origin, zero fallback).
    use super::*;
    use crate::board::StackMeter;
    use shared_types::eval::{Controller, Status};
    use shared_types::image::decode;
    use shared_types::protocol::{decode_frame, FrameEvent, Reply, Request, State};
    use std::collections::VecDeque;
    use std::vec::Vec;

    struct MockLink {
        rx: VecDeque<u8>,
        tx: Vec<u8>,
    }

    impl Link for MockLink {
        fn read_byte(&mut self) -> u8 {
            self.rx
                .pop_front()
                .expect("the test's input ends with Shutdown")
        }
        fn write_all(&mut self, bytes: &[u8]) {
            self.tx.extend_from_slice(bytes);
        }
    }

    /// Reports a fixed cost per measurement and counts them.
    struct MockMeter {
        calls: u32,
    }

    const COST: u32 = 123;

    impl Meter for MockMeter {
        fn measure<R>(&mut self, f: impl FnOnce() -> R) -> (R, u32) {
            self.calls += 1;
            (f(), COST)
        }
    }

    struct MockStack(u32);
    impl StackMeter for MockStack {
        fn peak_bytes(&self) -> u32 {
            self.0
        }
    }

    fn frame(req: &Request) -> Vec<u8> {
        let mut buf = [0u8; MAX_FRAME];
        encode_frame(req, &mut buf).unwrap().to_vec()
    }

    fn step(seq: u32, x: &[f32]) -> Vec<u8> {
        frame(&Request::Step {
            seq,
            x: State::from_slice(x).unwrap(),
        })
    }

    /// Runs one session over `input` (which must end with Shutdown) and returns the replies and the end.
    fn session(app: &mut App<'_>, input: &[Vec<u8>]) -> (Vec<Reply>, End, u32) {
        let mut link = MockLink {
            rx: input.iter().flatten().copied().collect(),
            tx: Vec::new(),
        };
        let mut meter = MockMeter { calls: 0 };
        let end = serve(app, &mut link, &mut meter);
        assert!(
            link.rx.is_empty(),
            "serve stops at Shutdown, the last frame"
        );
        let mut reader = Reader::new();
        let mut replies = Vec::new();
        for b in link.tx {
            if let Some(FrameEvent::Frame(f)) = reader.push(b) {
                replies.push(decode_frame::<Reply>(f).expect("a reply decodes"));
            }
        }
        (replies, end, meter.calls)
    }

    fn shutdown() -> Vec<u8> {
        frame(&Request::Shutdown)
    }

    #[test]
    fn steps_in_the_envelope_match_the_shared_evaluator_bit_for_bit() {
        let (mut app, boot) = crate::boot();
        let img = boot.expect("the default image is accepted");
        let mut reference = Controller::new(img);
        let states: [[f32; 2]; 3] = [[1.0, 0.0], [0.5, -0.25], [-2.0, 3.0]];
        let mut input: Vec<Vec<u8>> = states
            .iter()
            .enumerate()
            .map(|(k, x)| step(k as u32, x))
            .collect();
        input.push(shutdown());
        let (replies, end, calls) = session(&mut app, &input);
        assert_eq!(replies.len(), states.len());
        assert_eq!(calls, states.len() as u32);
        for (k, (r, x)) in replies.iter().zip(&states).enumerate() {
            let u = reference.step(x).expect("inside the ball");
            assert_eq!(r.seq, k as u32);
            assert_eq!(r.status, Status::Ok);
            assert_eq!(r.cost, COST);
            assert_eq!(r.u.as_slice().len(), 1);
            assert_eq!(r.u.as_slice()[0].to_bits(), u.as_slice()[0].to_bits());
        }
        // u = K x with K = [-4, -3.8] at the first state.
        assert_eq!(replies[0].u.as_slice(), &[-4.0]);
        match end {
            End::Shutdown(s) => {
                assert_eq!((s.ok, s.bad_frames, s.out_of_envelope), (3, 0, 0));
                assert_eq!(s.max_cost, COST);
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn bad_frames_change_nothing_and_the_loop_goes_on() {
        let (mut app, _) = crate::boot();
        let oversize = {
            let mut v = vec![0x55u8; MAX_FRAME + 10];
            v.push(0);
            v
        };
        let input = [
            step(0, &[1.0, 0.0]),
            step(5, &[1.0, 0.0]),      // wrong seq
            vec![1, 2, 3, 0],          // not a message
            oversize,                  // longer than any frame
            vec![0, 0],                // empty frames are ignored
            step(1, &[f32::NAN, 0.0]), // not finite
            step(1, &[1.0]),           // wrong dimension
            step(1, &[0.0, 1.0]),
            shutdown(),
        ];
        let (replies, end, calls) = session(&mut app, &input);
        let got: Vec<(u32, Status)> = replies.iter().map(|r| (r.seq, r.status)).collect();
        assert_eq!(
            got,
            [
                (0, Status::Ok),
                (5, Status::BadFrame),
                (1, Status::BadFrame),
                (1, Status::BadFrame),
                (1, Status::BadFrame),
                (1, Status::BadFrame),
                (1, Status::Ok),
            ]
        );
        // A bad frame costs nothing and answers the image's fallback at the last state (zero here).
        for r in &replies[1..6] {
            assert_eq!(r.cost, 0);
            assert_eq!(r.u.as_slice(), &[0.0]);
        }
        assert_eq!(replies[6].u.as_slice(), &[-3.8]);
        assert_eq!(app.expected_seq(), 2);
        // The NaN and wrong-dimension steps were evaluated (and refused by the evaluator).
        assert!(calls >= 2);
        match end {
            End::Shutdown(s) => assert_eq!((s.ok, s.bad_frames), (2, 5)),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_state_outside_every_ball_gets_out_of_envelope_and_the_fallback() {
        let (mut app, _) = crate::boot();
        let input = [step(0, &[20.0, 0.0]), step(1, &[1.0, 0.0]), shutdown()];
        let (replies, end, _) = session(&mut app, &input);
        assert_eq!(replies[0].status, Status::OutOfEnvelope);
        assert_eq!(replies[0].u.as_slice(), &[0.0]);
        assert_eq!(replies[0].cost, COST);
        // Out of the envelope is latched: the run left the certified cover.
        assert_eq!(replies[1].status, Status::OutOfEnvelope);
        match end {
            End::Shutdown(s) => assert_eq!(s.out_of_envelope, 2),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_rejected_image_answers_image_rejected_with_the_build_time_fallback() {
        let garbage = [0xA5u8; 64];
        let (mut app, boot) = App::new(&garbage, 3);
        assert!(boot.is_err());
        let input = [
            step(0, &[1.0, 0.0]),
            vec![9, 9, 0],
            step(1, &[1.0]),
            shutdown(),
        ];
        let (replies, end, calls) = session(&mut app, &input);
        assert_eq!(calls, 0, "nothing is evaluated");
        for r in &replies {
            assert_eq!(r.status, Status::ImageRejected);
            assert_eq!(r.u.as_slice(), &[0.0; 3]);
            assert_eq!(r.cost, 0);
        }
        assert_eq!(replies.iter().map(|r| r.seq).collect::<Vec<_>>(), [0, 1, 1]);
        match end {
            End::Shutdown(s) => assert_eq!((s.rejected, s.bad_frames), (2, 1)),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn the_embedded_image_is_aligned_and_decodes() {
        let img = crate::image::image();
        assert_eq!(img.as_ptr() as usize % 8, 0);
        assert!(decode(img).is_ok());
        assert_eq!(MockStack(96).peak_bytes(), 96);
    }
}
