//! The closed loop: the plant on the host, the controller on the (emulated) target, and the host's own
//! evaluation of the same image alongside, compared bit for bit every step. The plant is a sampled
//! linear one ([`run`]) or any one-period step ([`run_with`], e.g. a nonlinear plant's
//! [`crate::nonlinear::PlantFlow`]); states and inputs are the plant's (an image with model maps runs
//! `step_plant`).

use crate::plant::DiscretePlant;
use crate::qemu::Qemu;
use crate::HilError;
use shared_types::eval::{Controller, Input, Status};
use shared_types::image::Image;
use shared_types::protocol::{InputVec, Reply};

/// What the firmware should answer, computed on the host with `shared_types::eval` in f32: the same rules
/// as the firmware's `app` module (`step_plant`; the fallback replaces the input whenever the step is not
/// `Ok`).
pub struct HostEvaluator<'a> {
    controller: Controller<'a>,
    last_u: Input,
    last_x: Option<Vec<f32>>,
}

impl<'a> HostEvaluator<'a> {
    /// A fresh evaluator, as the firmware is after boot.
    pub fn new(image: Image<'a>) -> Self {
        let m = image.plant_m();
        Self {
            controller: Controller::new(image),
            last_u: Input::zero(m),
            last_x: None,
        }
    }

    /// The location of the evaluator's current row (`Controller::location`), as the reply carries it.
    pub fn location(&self) -> u8 {
        self.controller.location() as u8
    }

    /// Whether the image's terminal law has taken over (`Controller::in_terminal_phase`).
    pub fn in_terminal_phase(&self) -> bool {
        self.controller.in_terminal_phase()
    }

    /// The controller's own states ζ as the evaluator keeps them (empty without a dynamic extension).
    pub fn extension(&self) -> Vec<f64> {
        self.controller
            .extension()
            .iter()
            .map(|&v| f64::from(v))
            .collect()
    }

    /// One accepted step: the status and the input the firmware must reply.
    pub fn step(&mut self, x: &[f32]) -> (Status, Input) {
        let (status, u) = match self.controller.step_plant(x) {
            Ok(u) => (Status::Ok, u),
            Err(s) => (s, self.controller.fallback(x, &self.last_u)),
        };
        if status != Status::BadFrame {
            self.last_u = u;
            self.last_x = Some(x.to_vec());
        }
        (status, u)
    }

    /// The input the firmware replies to a bad frame: the fallback at the last accepted state.
    pub fn bad_frame_input(&self) -> Input {
        let x = self.last_x.as_deref().unwrap_or(&[]);
        self.controller.fallback(x, &self.last_u)
    }
}

/// `u` as it travels on the wire.
pub fn wire(u: &Input) -> InputVec {
    InputVec::from_slice(u.as_slice()).unwrap_or_default()
}

/// The record of a closed-loop run.
#[derive(Clone, Debug, Default)]
pub struct Trace {
    /// Plant states, `x(0)` … `x(steps)`.
    pub states: Vec<Vec<f64>>,
    /// The firmware's replies, one per step.
    pub replies: Vec<Reply>,
    /// The controller's own states ζ at each sample (`ζ(0)` … `ζ(steps)`), as the host evaluator keeps
    /// them in step with the firmware: before the step at that sample, so ξ of sample k is read from
    /// `states[k]` and `controller_states[k]`. Empty vectors for an image without a dynamic extension.
    pub controller_states: Vec<Vec<f64>>,
}

impl Trace {
    /// The last state.
    pub fn last_state(&self) -> &[f64] {
        self.states.last().map_or(&[], |v| v.as_slice())
    }

    /// Largest reported cost among replies with `status`.
    pub fn max_cost(&self, status: Status) -> Option<u32> {
        self.replies
            .iter()
            .filter(|r| r.status == status)
            .map(|r| r.cost)
            .max()
    }
}

/// A check that failed, as an error.
pub fn check(ok: bool, what: impl FnOnce() -> String) -> Result<(), HilError> {
    if ok {
        Ok(())
    } else {
        Err(HilError::Check(what()))
    }
}

/// One period: sample `x` (rounded to f32), send it with `seq`, check the reply against `expect`
/// (status and input bit for bit, echoed `seq`), and return the reply.
pub fn exchange(
    q: &mut Qemu,
    seq: u32,
    x: &[f64],
    expect: impl FnOnce(&[f32]) -> (Status, Input),
) -> Result<Reply, HilError> {
    let xf: Vec<f32> = x.iter().map(|&v| v as f32).collect();
    let reply = q.step(seq, &xf)?;
    let (status, u) = expect(&xf);
    check(reply.seq == seq, || {
        format!("seq {seq}: reply carries seq {}", reply.seq)
    })?;
    check(reply.status == status, || {
        format!("seq {seq}: status {:?}, host says {status:?}", reply.status)
    })?;
    check(reply.u == wire(&u), || {
        format!(
            "seq {seq} at x = {xf:?}: firmware u = {:?}, host u = {:?} (bitwise)",
            reply.u,
            u.as_slice()
        )
    })?;
    check(status != Status::Ok || reply.cost > 0, || {
        format!("seq {seq}: Ok step with cost 0")
    })?;
    Ok(reply)
}

/// Runs `steps` periods from `x0`, sequence numbers from `first_seq`: each reply is checked against the
/// host evaluator and its input applied to the plant (zero-order hold over one period).
pub fn run(
    q: &mut Qemu,
    plant: &DiscretePlant,
    host: &mut HostEvaluator<'_>,
    x0: &[f64],
    first_seq: u32,
    steps: usize,
) -> Result<Trace, HilError> {
    run_with(q, host, x0, first_seq, steps, |x, u| Ok(plant.step(x, u)))
}

/// [`run`] with the plant given as its one-period step `plant(x, u)` (the state one sample period later
/// with `u` held); an error of the plant ends the run.
pub fn run_with(
    q: &mut Qemu,
    host: &mut HostEvaluator<'_>,
    x0: &[f64],
    first_seq: u32,
    steps: usize,
    plant: impl FnMut(&[f64], &[f64]) -> Result<Vec<f64>, String>,
) -> Result<Trace, HilError> {
    run_until(q, host, x0, first_seq, steps, plant, |_, _| false)
}

/// [`run_with`] that also ends after the first sample at which `done(x, controller states)` holds (the
/// start included): a test that judges a run only up to Goal need not exchange the periods after it.
pub fn run_until(
    q: &mut Qemu,
    host: &mut HostEvaluator<'_>,
    x0: &[f64],
    first_seq: u32,
    steps: usize,
    mut plant: impl FnMut(&[f64], &[f64]) -> Result<Vec<f64>, String>,
    mut done: impl FnMut(&[f64], &[f64]) -> bool,
) -> Result<Trace, HilError> {
    let mut trace = Trace {
        states: vec![x0.to_vec()],
        replies: Vec::with_capacity(steps),
        controller_states: vec![host.extension()],
    };
    let mut x = x0.to_vec();
    for k in 0..steps {
        if done(&x, &host.extension()) {
            break;
        }
        let seq = first_seq.wrapping_add(k as u32);
        let reply = exchange(q, seq, &x, |xf| host.step(xf))?;
        let u: Vec<f64> = reply.u.as_slice().iter().map(|&v| v as f64).collect();
        x = plant(&x, &u).map_err(|e| HilError::Check(format!("seq {seq}: the plant: {e}")))?;
        trace.states.push(x.clone());
        trace.replies.push(reply);
        trace.controller_states.push(host.extension());
    }
    Ok(trace)
}
