//! The evaluator: the one piece of code that computes the control input from a validated [`Image`], run in
//! f32 both by host verification and by the firmware (DESIGN §4, §5). Also the per-period answer type
//! [`Status`] and the fixed-size [`Input`].
//!
//! Feedforward mode implements Algorithm 2 with the law (3.5)–(3.6):
//! 1. at κ = 0, among the trajectories whose ball `‖x − x̃_i(0)‖_P ≤ δ_i` (P of the trajectory's first
//!    location) contains x, select the nearest in that metric (ties: the lowest index); none → the answer
//!    is [`Status::OutOfEnvelope`], latched until [`Controller::reset`];
//! 2. at every step, `u = K_ℓ x + v_i(κ)` where ℓ = ℓ_i(κ) is the location of the segment holding row κ
//!    (hybrid runs, (4.41)–(4.42); a single-location image always uses K_0). The controller keeps a cursor
//!    on the active segment and moves it forward when κ passes the segment's last row, so a step costs no
//!    search over segments;
//! 3. past the last row, the image's [`Terminal`] behaviour.
//!
//! Both modes: with a terminal law ([`crate::terminal`], section 11) every step first tests whether x lies
//! in the law's certified ellipsoid in Goal; if so, the terminal law gives the input and the controller is
//! in its terminal phase, where a state outside the ellipsoid is out of the envelope (this step only).
//!
//! PWA-feedback mode (Ch. 6, law (6.1)) is pure feedback: at every step, locate x (a bounded-depth tree
//! walk, then the envelope test against the leaf's certified balls, see [`crate::pwa`]); inside a ball,
//! `u = K_j x + θ0_j` with `K_j = K + θ_j` of that ball's partition j; otherwise [`Status::OutOfEnvelope`]
//! for this step only (nothing is latched, and there is no default region).
//!
//! With model maps ([`crate::maps`], a feedback-linearizable or differentially flat plant, §3.1.2),
//! [`Controller::step_plant`] wraps the feedforward law: ξ = coords(x, ζ), the feedforward law above on ξ
//! (selecting with the image's whitened selection test when it has one, [`Controller::select_maps`])
//! gives w, and (u, ζ⁺) = input_map(x, ζ, w); where the law would apply the fallback, the image's fallback
//! (in the plant's input space) is applied without running `input_map`. ζ are the controller's own states
//! (a dynamic extension, `n_ext ≤ MAX_EXT` of them, none for a feedback-linearizable plant): ζ0 (stored in
//! the section) at [`Controller::new`] and [`Controller::reset`], ζ ← ζ⁺ when a step that ran `input_map`
//! is accepted, unchanged by an error and by the fallback ([`Controller::extension`] reads them). Without
//! model maps `step_plant` is `step`.
//!
//! Distances are compared squared (`(x − c)ᵀP(x − c) ≤ δ²`), so no square root is needed. Arithmetic is
//! plain f32 multiply and add in a fixed order, without fused multiply-add, so host and Cortex-M4F give the
//! same bits; the matrix–vector products (selection, law, PWA law, linear fallback) run on nalgebra views
//! in the module `linalg`, whose doc states their summation order. Every loop is bounded by the capacities in [`crate::capacity`]; nothing allocates or panics.
//!
//! Errors never advance the step counter κ, nor change the controller states ζ.
#![allow(non_snake_case)]

use crate::capacity::{MAX_EXT, MAX_M, MAX_N};
use crate::image::{Exit, Fallback, Image, Mode, ModelMaps, Terminal};
use crate::linalg;
use crate::program::Workspace;
use crate::pwa::Region;
use crate::raw::{f32_span, floats};
use crate::terminal::TerminalLaw;

/// The firmware's answer every period besides `Ok(u)`. Shared by firmware and host (wire value = `u8`).
#[repr(u8)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    /// An input was computed.
    Ok = 0,
    /// The state is outside the certified envelope (feedforward: in no ball at κ = 0; PWA: in no certified
    /// ball of its leaf, or sent outside by the tree), or the input overflowed.
    OutOfEnvelope = 1,
    /// The request was malformed (used by the protocol layer; the evaluator also returns it for a state of
    /// the wrong length or with non-finite components).
    BadFrame = 2,
    /// The stored image failed validation; the firmware applies [`rejected_image_input`].
    ImageRejected = 3,
}

impl Status {
    /// The status with this wire value, if any.
    pub const fn from_u8(b: u8) -> Option<Status> {
        match b {
            0 => Some(Status::Ok),
            1 => Some(Status::OutOfEnvelope),
            2 => Some(Status::BadFrame),
            3 => Some(Status::ImageRejected),
            _ => None,
        }
    }
}

impl core::fmt::Display for Status {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Status::Ok => "ok",
            Status::OutOfEnvelope => "out of envelope",
            Status::BadFrame => "bad frame",
            Status::ImageRejected => "image rejected",
        })
    }
}

/// A control input: up to [`MAX_M`] values, of which the first `len()` are meaningful (the rest are 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Input {
    u: [f32; MAX_M],
    m: u8,
}

impl Input {
    /// Zero input of dimension `min(m, MAX_M)`.
    pub const fn zero(m: usize) -> Input {
        let m = if m > MAX_M { MAX_M } else { m };
        Input {
            u: [0.0; MAX_M],
            m: m as u8,
        }
    }

    /// Input with these values; `None` if longer than [`MAX_M`].
    pub fn from_slice(u: &[f32]) -> Option<Input> {
        let mut out = Input::zero(u.len());
        out.u.get_mut(..u.len())?.copy_from_slice(u);
        Some(out)
    }

    /// The meaningful values.
    pub fn as_slice(&self) -> &[f32] {
        self.u.get(..self.m as usize).unwrap_or(&self.u)
    }

    /// Input dimension.
    pub fn len(&self) -> usize {
        self.m as usize
    }

    /// Whether the input has dimension 0.
    pub fn is_empty(&self) -> bool {
        self.m == 0
    }

    /// All [`MAX_M`] slots (those past `len()` are 0).
    pub fn values(&self) -> [f32; MAX_M] {
        self.u
    }
}

/// The build-time fallback: the input the firmware applies when its image is rejected (zero, of dimension
/// `min(m, MAX_M)`; the firmware passes the `m` it was built for, or 0 if it knows none).
pub const fn rejected_image_input(m: usize) -> Input {
    Input::zero(m)
}

/// Controller state over a validated image (either mode).
#[derive(Clone, Copy, Debug)]
pub struct Controller<'a> {
    image: Image<'a>,
    kappa: u32,
    active: Option<u16>,
    /// Segment of the active trajectory holding row κ (the cursor of the module doc).
    segment: u16,
    /// κ at which the active segment began (images with segment exits).
    seg_kappa: u32,
    out_of_envelope: bool,
    /// Whether the terminal law has taken over (images with a terminal law).
    terminal: bool,
    last_u: Input,
    /// The controller's own states ζ (model maps with a dynamic extension; the first `n_ext` are used):
    /// ζ0 at reset, ζ⁺ of `input_map` after every accepted step that ran it.
    ext: [f32; MAX_EXT],
    /// The model programs' working memory, kept across steps (never read before written within an
    /// evaluation, so it is not state of the law).
    work: Workspace,
}

impl<'a> Controller<'a> {
    /// A controller at κ = 0 with no trajectory selected and its controller states (if any) at ζ0.
    pub fn new(image: Image<'a>) -> Controller<'a> {
        let m = image.plant_m();
        let mut ext = [0.0f32; MAX_EXT];
        if let Some(maps) = image.maps.as_ref() {
            for (e, v) in ext.iter_mut().zip(maps.ext_inits()) {
                *e = v;
            }
        }
        Controller {
            image,
            kappa: 0,
            active: None,
            segment: 0,
            seg_kappa: 0,
            out_of_envelope: false,
            terminal: false,
            last_u: Input::zero(m),
            ext,
            work: Workspace::new(),
        }
    }

    /// The image.
    pub fn image(&self) -> &Image<'a> {
        &self.image
    }

    /// Back to κ = 0: forget the selected trajectory, the out-of-envelope latch and the last input, and
    /// put the controller states back to ζ0.
    pub fn reset(&mut self) {
        *self = Controller::new(self.image);
    }

    /// κ: the number of successful steps since reset (the index of the next step); saturates.
    pub fn step_index(&self) -> u32 {
        self.kappa
    }

    /// The trajectory selected at κ = 0, if any.
    pub fn active_trajectory(&self) -> Option<u16> {
        self.active
    }

    /// The location of the segment the last step's row belongs to: the discrete input a plant with forced
    /// switching takes (§4.2.1, the location by the table). 0 before a trajectory is selected, for
    /// one-location images and for PWA images. Reads the segment cursor; the step does no extra work.
    pub fn location(&self) -> usize {
        if self.active.is_none() || self.image.mode() != Mode::Feedforward {
            return 0;
        }
        self.image
            .segment(self.segment as usize)
            .map_or(0, |g| g.location)
    }

    /// Whether the terminal law has taken over since reset ([`crate::terminal`]).
    pub fn in_terminal_phase(&self) -> bool {
        self.terminal
    }

    /// The controller's own states ζ (the first `n_ext` values; empty without a dynamic extension): ζ0
    /// after reset, then ζ⁺ of the last accepted step that ran `input_map` ([`Controller::step_plant`]).
    pub fn extension(&self) -> &[f32] {
        let ne = self.image.maps.as_ref().map_or(0, ModelMaps::n_ext);
        self.ext.get(..ne).unwrap_or(&[])
    }

    /// The last input returned by [`Controller::step`] (zero after reset).
    pub fn last_input(&self) -> Input {
        self.last_u
    }

    /// Algorithm 2, step 2: the trajectory whose ball contains `x` and is nearest in its metric,
    /// `argmin_i (x − x̃_i(0))ᵀ P_{ℓ_i(0)} (x − x̃_i(0))` subject to that being ≤ δ_i²; ties go to the lowest
    /// index. `None` if no ball contains `x` or `x` has the wrong length. Pure; does not change state.
    pub fn select(&self, x: &[f32]) -> Option<u16> {
        let img = &self.image;
        // Validated images have 1 ≤ n ≤ MAX_N; the clamp lets the compiler drop the zero-chunk panic path.
        let n = img.n().clamp(1, MAX_N);
        if x.len() != n {
            return None;
        }
        // One location, so one P for every ball: the fixed-size path for n = 4, the state dimension of the
        // planar vehicles (Examples 4.8, 4.9 and their variants), whose images have the most balls. Each
        // dimension so served costs its own unrolled copy in flash (about 500 bytes for n = 4; n = 8 is
        // served only on the model-maps path, `select_maps`).
        if img.n_locations() == 1 && n == 4 {
            return self.select_fixed::<4>(x);
        }
        let p = img.payload();
        let mut best: Option<u16> = None;
        let mut best_d2 = f32::INFINITY;
        let mut e = [0.0f32; MAX_N];
        for t in 0..img.n_trajectories() {
            let centre = f32_span(p.centre, t * n, n);
            for ((ei, &xi), ci) in e.iter_mut().zip(x).zip(floats(centre)) {
                *ei = xi - ci;
            }
            // A one-location image has location 0 everywhere (decode checks every segment's location):
            // no segment lookup in this loop over all balls.
            let l = if img.n_locations() == 1 {
                0
            } else {
                let (s0, _) = img.trajectory_segments(t);
                img.segment(s0).map_or(0, |s| s.location)
            };
            let P = f32_span(p.P, l * n * n, n * n);
            let d2 = linalg::quadratic_form(P, &e, n);
            let delta = img.delta(t);
            if d2 <= delta * delta && d2 < best_d2 {
                best_d2 = d2;
                best = Some(t as u16);
            }
        }
        best
    }

    /// The selection the model-maps step runs ([`Controller::step_plant`]): the image's whitened
    /// selection test when it carries one ([`crate::selection`], section 13), else [`Controller::select`]
    /// with its unrolled path also for n = 8 (the same answers as `select`). Only the model-maps step
    /// calls it, so a firmware whose image has no model maps carries neither. Pure; does not change state.
    pub fn select_maps(&self, x: &[f32]) -> Option<u16> {
        let img = &self.image;
        if let Some(test) = img.selection_test() {
            let first_location = |t: usize| {
                let (s0, _) = img.trajectory_segments(t);
                img.segment(s0).map_or(0, |s| s.location)
            };
            return test.select(img.dims(), first_location, x);
        }
        if self.image.n_locations() == 1 && self.image.n() == 8 {
            return self.select_fixed::<8>(x);
        }
        self.select(x)
    }

    /// [`Controller::select`] for a one-location image of state dimension N (x has N values): P read from
    /// the image once, then per ball e = x − c and the quadratic form unrolled, with P held in registers
    /// across the balls. The same f32 operations in the same order as the general loop, so the same
    /// answer; it only costs less per ball, and the selection tests every ball at κ = 0.
    #[inline(never)]
    fn select_fixed<const N: usize>(&self, x: &[f32]) -> Option<u16> {
        let img = &self.image;
        let p = img.payload();
        let x = x.get(..N)?;
        let P = linalg::matrix_fixed::<N>(f32_span(p.P, 0, N * N));
        let mut best: Option<u16> = None;
        let mut best_d2 = f32::INFINITY;
        let balls = p.centre.chunks_exact(4 * N).zip(floats(p.delta));
        for (t, (centre, delta)) in balls.take(img.n_trajectories()).enumerate() {
            let mut e = [0.0f32; N];
            for ((ei, &xi), ci) in e.iter_mut().zip(x).zip(floats(centre)) {
                *ei = xi - ci;
            }
            let d2 = linalg::quadratic_form_fixed(&P, &e);
            if d2 <= delta * delta && d2 < best_d2 {
                best_d2 = d2;
                best = Some(t as u16);
            }
        }
        best
    }

    /// PWA point location of `x` (see [`Image::locate`]): `None` for a feedforward image or an unusable
    /// `x`. Pure; does not change state.
    pub fn locate(&self, x: &[f32]) -> Option<Region> {
        self.image.locate(x)
    }

    /// The location of table row `row` of trajectory `t`: moves the segment cursor forward (within the
    /// trajectory's segments) until its segment holds `row`. Rows only grow between resets, so the cursor
    /// moves at most once per step; the loop bound is the trajectory's segment count.
    fn row_location(&mut self, t: usize, row: usize) -> usize {
        let img = &self.image;
        if img.n_locations() == 1 {
            return 0;
        }
        let (s0, count) = img.trajectory_segments(t);
        // max/min, not clamp: clamp's `min <= max` assertion is a panic path the firmware must not link
        // (for validated images count ≥ 1, and both give the same s).
        let mut s = (self.segment as usize)
            .max(s0)
            .min((s0 + count).saturating_sub(1));
        for _ in 0..count {
            match img.segment(s) {
                Some(g) if row >= g.first_row.saturating_add(g.len) && s + 1 < s0 + count => s += 1,
                _ => break,
            }
        }
        self.segment = s as u16;
        img.segment(s).map_or(0, |g| g.location)
    }

    /// `u = K_ℓ x + v` for table row `row` in location `l` ((3.5)–(3.6), location per (4.41)).
    fn law(&self, row: usize, l: usize, x: &[f32]) -> Input {
        let img = &self.image;
        let p = img.payload();
        let (n, m) = (img.n().clamp(1, MAX_N), img.m().clamp(1, MAX_M));
        let K = f32_span(p.K, l * m * n, m * n);
        let v = f32_span(p.v, row * m, m);
        let mut out = Input::zero(m);
        linalg::affine(K, x, v, n, m, &mut out.u);
        out
    }

    /// One control period. `x` must have length n and be finite, else `Err(BadFrame)`. Feedforward:
    /// returns `Err(OutOfEnvelope)` if no ball contained the state at κ = 0 (latched until reset). PWA:
    /// returns `Err(OutOfEnvelope)` for this step if the state is outside the certified envelope. Both:
    /// `Err(OutOfEnvelope)` if the input is not finite. On success κ advances and the input is remembered
    /// for [`Fallback::Hold`]. With a terminal law, a state in its ellipsoid gets the terminal law's
    /// input first, and in the terminal phase a state outside it is `Err(OutOfEnvelope)` (module doc).
    /// This is the law in the image's own coordinates: for an image with model maps, `x` is ξ and the
    /// answer is w; the plant's loop calls [`Controller::step_plant`].
    pub fn step(&mut self, x: &[f32]) -> Result<Input, Status> {
        self.step_for::<true>(x)
    }

    /// [`Controller::step`], choosing at build time whether the PWA step is linked: with `PWA` false (a
    /// firmware whose decoder refuses PWA images, [`crate::image::decode_for`]), a PWA image, which then
    /// cannot have been decoded, gets `Err(OutOfEnvelope)` and point location takes no flash.
    pub fn step_for<const PWA: bool>(&mut self, x: &[f32]) -> Result<Input, Status> {
        if let Some(law) = self.image.terminal_law() {
            if let Some(answer) = self.step_terminal(&law, x) {
                return answer;
            }
        }
        if self.image.mode() != Mode::Feedforward {
            return if PWA {
                self.step_pwa(x)
            } else {
                Err(Status::OutOfEnvelope)
            };
        }
        if x.len() != self.image.n() || !x.iter().all(|v| v.is_finite()) {
            return Err(Status::BadFrame);
        }
        self.feedforward(
            x,
            Self::select,
            |c, u| c.accept(u),
            |c| {
                let u = c.fallback(x, &c.last_u);
                c.accept(u)
            },
        )
    }

    /// One control period of the plant: `x` is the plant's state ([`Image::plant_n`] values) and the
    /// answer the plant's input ([`Image::plant_m`] values). Without model maps exactly
    /// [`Controller::step`]. With them: `x` must have `n_plant` finite values, else `Err(BadFrame)`;
    /// ξ = coords(x, ζ), `Err(OutOfEnvelope)` if not finite; the feedforward law of `step` on ξ gives w
    /// (`Err(OutOfEnvelope)` if not finite); (u, ζ⁺) = input_map(x, ζ, w), `Err(OutOfEnvelope)` if any
    /// value is not finite; otherwise ζ ← ζ⁺ and u is the answer. Where the law applies the fallback, the
    /// image's fallback is applied to the plant directly and ζ is left as it is. κ and the remembered
    /// input as for `step`; an error changes neither κ nor ζ.
    pub fn step_plant(&mut self, x: &[f32]) -> Result<Input, Status> {
        self.step_plant_for::<true>(x)
    }

    /// [`Controller::step_plant`] with the PWA step linked only when `PWA` ([`Controller::step_for`]).
    pub fn step_plant_for<const PWA: bool>(&mut self, x: &[f32]) -> Result<Input, Status> {
        match self.image.maps {
            None => self.step_for::<PWA>(x),
            Some(maps) => self.step_maps(&maps, x),
        }
    }

    /// [`Controller::step_plant`] with model maps; out of line, so that `step`'s code is not mixed with it.
    #[inline(never)]
    fn step_maps(&mut self, maps: &ModelMaps<'a>, x: &[f32]) -> Result<Input, Status> {
        let (n, m) = (
            self.image.n().clamp(1, MAX_N),
            self.image.m().clamp(1, MAX_M),
        );
        let (np, mp, ne) = (
            maps.n_plant().clamp(1, MAX_N),
            maps.m_plant().clamp(1, MAX_M),
            maps.n_ext().min(MAX_EXT),
        );
        if x.len() != np || !x.iter().all(|v| v.is_finite()) {
            return Err(Status::BadFrame);
        }
        // The slots of both programs: x, then the controller's states ζ as this step reads them (ζ
        // changes only once u is accepted), then w; coords reads the first np + ne of them.
        let mut slots = [0.0f32; MAX_N + MAX_EXT + MAX_M];
        for (s, &v) in slots.iter_mut().zip(x) {
            *s = v;
        }
        for (s, &v) in slots.iter_mut().skip(np).zip(self.ext.iter().take(ne)) {
            *s = v;
        }
        let mut xi_buf = [0.0f32; MAX_N];
        let (Some(xi), Some(coords_in)) = (xi_buf.get_mut(..n), slots.get(..np + ne)) else {
            return Err(Status::OutOfEnvelope);
        };
        // One working memory for both programs of the step (its memo: both need the same angles).
        if maps
            .coords()
            .eval_with(coords_in, xi, &mut self.work)
            .is_err()
            || !xi.iter().all(|v| v.is_finite())
        {
            return Err(Status::OutOfEnvelope);
        }
        let input_map = maps.input_map();
        self.feedforward(
            xi,
            Self::select_maps,
            |c, w| {
                if !w.as_slice().iter().all(|v| v.is_finite()) {
                    return Err(Status::OutOfEnvelope);
                }
                for (s, &v) in slots.iter_mut().skip(np + ne).zip(w.as_slice()) {
                    *s = v;
                }
                // Its outputs: u, then ζ⁺.
                let mut outputs = [0.0f32; MAX_M + MAX_EXT];
                let (Some(inputs), Some(out)) =
                    (slots.get(..np + ne + m), outputs.get_mut(..mp + ne))
                else {
                    return Err(Status::OutOfEnvelope);
                };
                if input_map.eval_with(inputs, out, &mut c.work).is_err() {
                    return Err(Status::OutOfEnvelope);
                }
                let Some((u_out, next)) = out.split_at_checked(mp) else {
                    return Err(Status::OutOfEnvelope);
                };
                if !next.iter().all(|v| v.is_finite()) {
                    return Err(Status::OutOfEnvelope);
                }
                let mut u = Input::zero(mp);
                for (o, &v) in u.u.iter_mut().zip(u_out) {
                    *o = v;
                }
                let u = c.accept(u)?;
                for (e, &v) in c.ext.iter_mut().zip(next) {
                    *e = v;
                }
                Ok(u)
            },
            |c| {
                let u = c.fallback(x, &c.last_u);
                c.accept(u)
            },
        )
    }

    /// The feedforward law of one step at the (finite, length-n) state `x`: selection at κ = 0 by
    /// `select` (one of the two with the same answers) and its latch, the table row (or exits), the
    /// terminal behaviour; then `law(self, u)` with the law's input or `fallback(self)` where the
    /// image's fallback applies. Closures rather than a returned enum, which
    /// the optimiser does not resolve branch by branch: this way `step` costs what its own inline code
    /// would.
    #[inline(always)]
    fn feedforward(
        &mut self,
        x: &[f32],
        select: impl FnOnce(&Self, &[f32]) -> Option<u16>,
        law: impl FnOnce(&mut Self, Input) -> Result<Input, Status>,
        fallback: impl FnOnce(&mut Self) -> Result<Input, Status>,
    ) -> Result<Input, Status> {
        if self.out_of_envelope {
            return Err(Status::OutOfEnvelope);
        }
        let t = match self.active {
            Some(t) => t,
            None => match select(self, x) {
                Some(t) => {
                    self.active = Some(t);
                    self.segment = self.image.trajectory_segments(t as usize).0 as u16;
                    t
                }
                None => {
                    self.out_of_envelope = true;
                    return Err(Status::OutOfEnvelope);
                }
            },
        };
        if self.image.has_exits() {
            return self.step_exits(t as usize, x, law, fallback);
        }
        let (start, len) = self.image.trajectory_rows(t as usize);
        let k = self.kappa as usize;
        if k < len || self.image.terminal() == Terminal::HoldLast {
            let row = start + k.min(len.saturating_sub(1));
            let l = self.row_location(t as usize, row);
            let u = self.law(row, l, x);
            law(self, u)
        } else {
            fallback(self)
        }
    }

    /// A feedforward step of an image with segment exits (internal switching, (4.41)–(4.42)): the cursor
    /// moves to the next segment of the trajectory when the active one has a guard exit and
    /// fl(Σⱼ âⱼx̂ⱼ − b̂) ≤ −θ (the next segment then starts at this sample, row 0), or when a table exit's
    /// rows are used up; the row is the segment's first row plus the samples since the segment began. A
    /// guard segment whose rows run out before its guard is seen leaves the certified envelope (latched);
    /// past the last segment's rows, the terminal behaviour. At most one move per segment of the
    /// trajectory per step.
    #[inline(never)]
    fn step_exits(
        &mut self,
        t: usize,
        x: &[f32],
        law: impl FnOnce(&mut Self, Input) -> Result<Input, Status>,
        fallback: impl FnOnce(&mut Self) -> Result<Input, Status>,
    ) -> Result<Input, Status> {
        let img = self.image;
        let n = img.n().clamp(1, MAX_N);
        let (s0, count) = img.trajectory_segments(t);
        let last = (s0 + count).saturating_sub(1);
        let mut s = (self.segment as usize).max(s0).min(last);
        for _ in 0..count {
            let Some(g) = img.segment(s) else { break };
            let local = self.kappa.saturating_sub(self.seg_kappa) as usize;
            if s >= last {
                break;
            }
            match img.exit(s) {
                Exit::Guard { a, b, theta, .. } => {
                    let mut acc = 0.0f32;
                    for (ai, &xi) in floats(a).zip(x).take(n) {
                        acc += ai * xi;
                    }
                    if acc - b <= -theta {
                        s += 1;
                        self.seg_kappa = self.kappa;
                        continue;
                    }
                }
                Exit::Table => {
                    if local >= g.len {
                        s += 1;
                        self.seg_kappa = self.seg_kappa.saturating_add(g.len as u32);
                        continue;
                    }
                }
            }
            break;
        }
        self.segment = s as u16;
        let Some(g) = img.segment(s) else {
            self.out_of_envelope = true;
            return Err(Status::OutOfEnvelope);
        };
        let local = self.kappa.saturating_sub(self.seg_kappa) as usize;
        let u = if local < g.len {
            self.law(g.first_row + local, g.location, x)
        } else if s < last {
            // A guard exit not seen within its rows: outside what was certified.
            self.out_of_envelope = true;
            return Err(Status::OutOfEnvelope);
        } else if img.terminal() == Terminal::HoldLast {
            self.law(g.first_row + g.len.saturating_sub(1), g.location, x)
        } else {
            return fallback(self);
        };
        law(self, u)
    }

    /// The terminal law's part of a step: `Some(answer)` when it decides the step (a bad state, a state in
    /// its ellipsoid, or the terminal phase), `None` to run the task's own law. Out of line, so that images
    /// without a terminal law pay one test.
    #[inline(never)]
    fn step_terminal(&mut self, law: &TerminalLaw<'a>, x: &[f32]) -> Option<Result<Input, Status>> {
        let (n, m) = (self.image.n(), self.image.m());
        if x.len() != n || !x.iter().all(|v| v.is_finite()) {
            return Some(Err(Status::BadFrame));
        }
        if law.accepts(x, n) {
            self.terminal = true;
            let mut u = Input::zero(m);
            law.law(x, n, m, &mut u.u);
            return Some(self.accept(u));
        }
        self.terminal.then_some(Err(Status::OutOfEnvelope))
    }

    /// The end of every step: a non-finite input is out of the envelope (κ does not advance); otherwise κ
    /// advances and the input is remembered for [`Fallback::Hold`].
    #[inline(always)]
    fn accept(&mut self, u: Input) -> Result<Input, Status> {
        if !u.as_slice().iter().all(|v| v.is_finite()) {
            return Err(Status::OutOfEnvelope);
        }
        self.kappa = self.kappa.saturating_add(1);
        self.last_u = u;
        Ok(u)
    }

    /// PWA-feedback step: locate, then `u = K_j x + θ0_j` (6.1). Kept out of line so that the feedforward
    /// path of [`Controller::step`] stays as it was.
    #[inline(never)]
    fn step_pwa(&mut self, x: &[f32]) -> Result<Input, Status> {
        let img = &self.image;
        let (n, m) = (img.n().clamp(1, MAX_N), img.m().clamp(1, MAX_M));
        if x.len() != n || !x.iter().all(|v| v.is_finite()) {
            return Err(Status::BadFrame);
        }
        let Region::Inside { partition, .. } = img.locate_in(x, n) else {
            return Err(Status::OutOfEnvelope);
        };
        let t = img.pwa();
        let j = partition as usize;
        let K = f32_span(t.gain, j * m * n, m * n);
        let theta0 = f32_span(t.offset, j * m, m);
        let mut u = Input::zero(m);
        linalg::affine(K, x, theta0, n, m, &mut u.u);
        self.accept(u)
    }

    /// The image's fallback input for state `x`, given the last applied input, in the plant's input
    /// space ([`Image::plant_m`] values; with model maps `x` is the plant's state and the law is never
    /// linear):
    /// * `Hold`: `last_u` (its first m values; missing or non-finite components become 0);
    /// * `Zero`: zero;
    /// * `Constant`: the stored input, whatever the state;
    /// * `Linear`: `K_fb (x − x_ref) + u_ref`, saturated to the input box if stored. If `x` has the wrong
    ///   length or a non-finite component, or the result is not finite, zero instead.
    pub fn fallback(&self, x: &[f32], last_u: &Input) -> Input {
        let img = &self.image;
        let (n, m) = (img.n().clamp(1, MAX_N), img.plant_m().clamp(1, MAX_M));
        let mut out = Input::zero(m);
        match img.fallback() {
            Fallback::Zero => {}
            Fallback::Constant { u } => {
                for (o, v) in out.u.iter_mut().zip(floats(u)) {
                    *o = v;
                }
            }
            Fallback::Hold => {
                for (o, &l) in out.u.iter_mut().zip(last_u.as_slice()).take(m) {
                    *o = if l.is_finite() { l } else { 0.0 };
                }
            }
            Fallback::Linear { K, x_ref, u_ref } => {
                if x.len() != n || !x.iter().all(|v| v.is_finite()) {
                    return out;
                }
                let mut e = [0.0f32; MAX_N];
                for ((ei, &xi), ri) in e.iter_mut().zip(x).zip(floats(x_ref)) {
                    *ei = xi - ri;
                }
                linalg::affine(K, &e, u_ref, n, m, &mut out.u);
                if let Some(b) = img.payload().input_box {
                    for ((uj, lo), hi) in out.u.iter_mut().zip(floats(b.lo)).zip(floats(b.hi)) {
                        // max/min, not clamp: clamp panics on NaN bounds (validated away, but be total).
                        *uj = uj.max(lo).min(hi);
                    }
                }
                if !out.as_slice().iter().all(|v| v.is_finite()) {
                    return Input::zero(m);
                }
            }
        }
        out
    }
}
