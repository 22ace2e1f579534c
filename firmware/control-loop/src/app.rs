//! What the loop does with each frame: the protocol and the evaluator's answer, without the hardware.
//!
//! One [`App`] holds either a running [`Controller`] over the validated image or, when the image was
//! rejected at boot, only the build-time fallback input. [`App::on_frame`] turns one received frame into
//! one [`Action`]:
//!
//! | situation                                        | status          | input `u`                      | seq      |
//! |--------------------------------------------------|-----------------|--------------------------------|----------|
//! | image rejected at boot (any frame but Shutdown)  | `ImageRejected` | build-time fallback (zero)     | advances on a valid step |
//! | frame oversize / not COBS / not a message        | `BadFrame`      | image fallback at the last state | unchanged |
//! | step with a wrong `seq`, wrong dimension, NaN    | `BadFrame`      | image fallback at the last state | unchanged |
//! | step, state in the envelope                      | `Ok`            | `K x + v_i(κ)` (with model maps: `input_map(x, K ξ + v_i(κ))`) | advances |
//! | step, state outside every ball (latched)         | `OutOfEnvelope` | image fallback at `x`          | advances |
//!
//! States and inputs are the plant's ([`Image::plant_n`], [`Image::plant_m`] values): the evaluator's
//! [`Controller::step_plant`] runs an image's model maps, if it has them, around its law. A firmware
//! whose embedded image has no model maps is built without `cfg(model_maps)` (`build.rs`) and calls
//! [`Controller::step`], which is `step_plant` for such an image, and decodes with
//! [`shared_types::image::decode_without_model_maps`], which refuses an image with model maps (such a
//! firmware would read the plant's state as the law's coordinates), so the program interpreter, its
//! decoder, the selection test and `libm` take no flash.
//!
//! The cost reported is that of the evaluation (step, and fallback when the step failed), in instructions;
//! 0 when nothing was evaluated.
//!
//! With `cfg(monitor)` (the image carries the task's monitor, `build.rs`), every step answered `Ok` or
//! `OutOfEnvelope` also updates the monitor with the state and replies its bounds, verdict and the
//! update's own cost; frames that carry no state leave it alone.

use crate::board::Meter;
use shared_types::eval::{rejected_image_input, Controller, Input, Status};
use shared_types::image::{Image, ImageError};
use shared_types::protocol::{
    decode_frame, FrameEvent, InputVec, MonitorReply, Reply, Request, State,
};

/// The task's monitor, when the embedded image carries one (`build.rs`, `cfg(monitor)`).
#[cfg(monitor)]
type TaskMonitor<'a> = Option<shared_types::monitor::Monitor<'a>>;
/// Without `cfg(monitor)` the monitor is not linked.
#[cfg(not(monitor))]
type TaskMonitor<'a> = core::marker::PhantomData<&'a ()>;

/// The monitor over the image's program and the arena `build.rs` sized, if both are there.
#[cfg(monitor)]
fn task_monitor<'a>(img: Option<&Image<'a>>) -> TaskMonitor<'a> {
    let prog = img?.monitor()?;
    shared_types::monitor::Monitor::new(prog, crate::image::monitor_arena()?).ok()
}

#[cfg(not(monitor))]
fn task_monitor<'a>(_: Option<&Image<'a>>) -> TaskMonitor<'a> {
    core::marker::PhantomData
}

/// The monitor's update on an accepted state, measured on its own.
#[cfg(monitor)]
fn monitor_step<M: Meter>(
    m: &mut TaskMonitor<'_>,
    x: &[f32],
    meter: &mut M,
) -> Option<MonitorReply> {
    let m = m.as_mut()?;
    let (r, cost) = meter.measure(|| m.update(x));
    Some(MonitorReply::new(&r, cost))
}

#[cfg(not(monitor))]
fn monitor_step<M: Meter>(_: &mut TaskMonitor<'_>, _: &[f32], _: &mut M) -> Option<MonitorReply> {
    None
}

/// The image decoder (module doc), built for what the embedded image carries: model maps
/// (`cfg(model_maps)`), the task's monitor (`cfg(monitor)`) and PWA feedback (`cfg(pwa)`); an image with
/// any of them that this build lacks is refused, and the decoder of what it lacks is not linked.
fn decode(bytes: &[u8]) -> Result<Image<'_>, ImageError> {
    shared_types::image::decode_for::<{ cfg!(model_maps) }, { cfg!(monitor) }, { cfg!(pwa) }>(bytes)
}

/// One control period of the plant (module doc): `step_plant` where the image may have model maps.
#[cfg(model_maps)]
#[inline(always)]
fn step(c: &mut Controller<'_>, x: &[f32]) -> Result<Input, Status> {
    c.step_plant_for::<{ cfg!(pwa) }>(x)
}

/// One control period of the plant: the embedded image has no model maps, so `step_plant` is `step`.
#[cfg(not(model_maps))]
#[inline(always)]
fn step(c: &mut Controller<'_>, x: &[f32]) -> Result<Input, Status> {
    c.step_for::<{ cfg!(pwa) }>(x)
}

/// What to do after a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Action {
    /// Send this reply.
    Reply(Reply),
    /// End the session (exit the emulator with success).
    Shutdown,
}

/// Counters for the end-of-session log line.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Stats {
    /// Steps answered `Ok`.
    pub ok: u32,
    /// Steps answered `OutOfEnvelope`.
    pub out_of_envelope: u32,
    /// Frames answered `BadFrame` (or refused as bad while the image is rejected).
    pub bad_frames: u32,
    /// Steps answered `ImageRejected`.
    pub rejected: u32,
    /// Largest evaluation cost seen, in instructions.
    pub max_cost: u32,
}

// One instance for the whole program, and no heap to box into: the size difference does not matter.
#[allow(clippy::large_enum_variant)]
enum Engine<'a> {
    Running(Controller<'a>),
    Rejected(Input),
}

/// The firmware's state between frames.
pub struct App<'a> {
    engine: Engine<'a>,
    expected_seq: u32,
    last_x: Option<State>,
    last_u: Input,
    stats: Stats,
    monitor: TaskMonitor<'a>,
}

fn to_wire(u: &Input) -> InputVec {
    // Input and InputVec have the same capacity (MAX_M), so this never falls back to empty.
    InputVec::from_slice(u.as_slice()).unwrap_or_default()
}

impl<'a> App<'a> {
    /// Validates `image_bytes`; on failure the app answers every frame with `ImageRejected` and a zero input
    /// of dimension `rejected_m`.
    pub fn new(image_bytes: &'a [u8], rejected_m: usize) -> (Self, Result<Image<'a>, ImageError>) {
        let decoded = decode(image_bytes);
        let (engine, last_u) = match decoded {
            Ok(img) => (
                Engine::Running(Controller::new(img)),
                Input::zero(img.plant_m()),
            ),
            Err(_) => {
                let u = rejected_image_input(rejected_m);
                (Engine::Rejected(u), u)
            }
        };
        let app = App {
            engine,
            expected_seq: 0,
            last_x: None,
            last_u,
            stats: Stats::default(),
            monitor: task_monitor(decoded.as_ref().ok()),
        };
        (app, decoded)
    }

    /// Counters so far.
    pub fn stats(&self) -> Stats {
        self.stats
    }

    /// The sequence number the next step must carry.
    pub fn expected_seq(&self) -> u32 {
        self.expected_seq
    }

    /// The image's fallback at the last accepted state (used for frames that carry no usable state).
    fn fallback_at_last(&self) -> Input {
        match &self.engine {
            Engine::Running(c) => {
                let x = self.last_x.as_ref().map_or(&[][..], |x| x.as_slice());
                c.fallback(x, &self.last_u)
            }
            Engine::Rejected(u) => *u,
        }
    }

    /// The location of the evaluator's current row (the discrete input of forced switching); 0 when the
    /// image was rejected.
    fn location(&self) -> u8 {
        match &self.engine {
            Engine::Running(c) => c.location() as u8,
            Engine::Rejected(_) => 0,
        }
    }

    fn bad_frame(&mut self, seq: u32) -> Action {
        self.stats.bad_frames = self.stats.bad_frames.saturating_add(1);
        let (status, u) = match &self.engine {
            Engine::Rejected(u) => (Status::ImageRejected, *u),
            Engine::Running(_) => (Status::BadFrame, self.fallback_at_last()),
        };
        Action::Reply(Reply {
            seq,
            status,
            u: to_wire(&u),
            cost: 0,
            location: self.location(),
            monitor: None,
        })
    }

    /// Handles one frame event from the reader.
    pub fn on_frame<M: Meter>(&mut self, ev: FrameEvent<'_>, meter: &mut M) -> Action {
        let frame = match ev {
            FrameEvent::Oversize => return self.bad_frame(self.expected_seq),
            FrameEvent::Frame(f) => f,
        };
        let (seq, x) = match decode_frame::<Request>(frame) {
            Err(_) => return self.bad_frame(self.expected_seq),
            Ok(Request::Shutdown) => return Action::Shutdown,
            Ok(Request::Step { seq, x }) => (seq, x),
        };
        if seq != self.expected_seq {
            return self.bad_frame(seq);
        }
        let last_u = self.last_u;
        let (status, u, cost) = match &mut self.engine {
            Engine::Rejected(u) => {
                self.stats.rejected = self.stats.rejected.saturating_add(1);
                (Status::ImageRejected, *u, 0)
            }
            Engine::Running(c) => {
                let ((status, u), cost) = meter.measure(|| match step(c, x.as_slice()) {
                    Ok(u) => (Status::Ok, u),
                    Err(s) => (s, c.fallback(x.as_slice(), &last_u)),
                });
                (status, u, cost)
            }
        };
        match status {
            Status::BadFrame => return self.bad_frame(seq),
            Status::Ok => self.stats.ok = self.stats.ok.saturating_add(1),
            Status::OutOfEnvelope => {
                self.stats.out_of_envelope = self.stats.out_of_envelope.saturating_add(1)
            }
            Status::ImageRejected => {}
        }
        self.stats.max_cost = self.stats.max_cost.max(cost);
        let monitor = monitor_step(&mut self.monitor, x.as_slice(), meter);
        self.expected_seq = self.expected_seq.wrapping_add(1);
        self.last_x = Some(x);
        self.last_u = u;
        Action::Reply(Reply {
            seq,
            status,
            u: to_wire(&u),
            cost,
            location: self.location(),
            monitor,
        })
    }
}
