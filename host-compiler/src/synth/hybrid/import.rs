//! Person-made runs on a hybrid plant (§1.1.3; internal switching, §4.2.2: Def 4.22, Lemma 4.23,
//! Theorem 4.24): a recording (`synth --import`, `host-compiler play`) replayed on the automaton, split at
//! its events into the segments of the task's location path, and certified by the certificate the synth
//! path uses ([`super::certify_run`], [`crate::certify::internal`]).
//!
//! **What a recording is.** As for a one-location plant ([`crate::cover::certify_recording`]): the
//! initial state (stored as f32) and one row of reference inputs v(κ) per sample, the feedforward of the
//! tracking loop u = K_ℓ x + v (4.19) with ℓ the location the plant is in at that sample. The rows are
//! the nominal's tables, as the image would ship them (f32 values); `play` records the v in effect.
//!
//! **The replay** ([`replay`]). Segment 0 runs from x0 in the path's first location under the rows from
//! sample 0; the automaton's exact flow ([`crate::model::hybrid::Hybrid::flow`]) along its nominal finds
//! the period κₑ in which the run enters the guard of the path's first edge. The next segment starts at
//! the state that flow reaches at sample κₑ + 1 (after its event, rounded to f32, which the image stores),
//! in the next location, with the rows from sample κₑ + 1 on: each segment's table is the recording
//! shifted by the sample at which the run entered its location. Every segment but the last is the
//! *extended* segment of §4.2.2: its nominal continues past the event in its own location under the
//! recording's later rows, far enough that the certificate finds the sample κ_f whose tube lies inside
//! the guard (it keeps rows 0..κ_f). How far is chosen as `plan_run` chooses its targets: up to the first
//! sample d deep in the guard, d from [`super::GUARD_DEPTHS`], each tried and the largest certified δ
//! kept (a longer extension only adds rows of the location's flow under inputs meant for the next one,
//! which may run into Unsafe before the upper end of the certificate's bisection is inside the guard).
//! A run that takes another edge than the path's, switches more than once in a period, or never
//! switches, is refused, saying so. A recording that names each row's location (a
//! [`crate::trajectory::csv::LOCATION`] column, as `simulate` writes a hybrid run) must name the ones the
//! replay finds up to Goal, else it is refused at the first row that differs.
//!
//! **Where the next segment starts.** The replayed state after the event is one landing; the certificate
//! bounds every landing of runs near the nominal (item 4 of [`crate::certify::internal`]) against the
//! next segment's start, which may be any state the image stores. So each split is also tried with the
//! later segments restarted where `plan_run` starts them, at the centre of those landings
//! ([`Replay::centred`]), under the same rows. Both are nominals of the same recorded inputs; the person's
//! own run starts at the first ball's centre and is covered by whichever certifies the larger δ.
//!
//! **Forced switching** (§4.2.1, Theorem 4.17; Def 4.18 for a formula task). The controller chooses the
//! location, so the recording says which: its [`crate::trajectory::csv::LOCATION`] column names the
//! location of every row, the first the task's initial location. Rows in one location make a segment; a
//! change of location between rows κ − 1 and κ is a switch at sample κ by the forced edge between the
//! two (which must exist). The segments are simulated as `plan_forced` simulates its own
//! ([`super::shipped_nominal`], each from the previous one's end, the resets being the identity) and
//! certified by the same [`super::forced::certify_run`]. A recording without the column is refused by
//! name: reference inputs alone do not say when the controller switches. For a formula task the
//! recording must cover the whole horizon, over which the formula is judged.
//!
//! **One accept path.** An accepted recording is a [`HybridRun`] like those `plan_run` makes; it joins a
//! synthesis' runs through [`super::synthesize_hybrid`]'s accept test ([`super::admit`]) before the
//! automatic growth, and `play`'s cover directly.

use super::{certify_run, shipped_nominal, HybridRun, HybridTask};
use crate::certify::internal::{truncate, InternalCertificate};
use crate::model::Location;
use crate::trajectory::csv::Recording;
use crate::trajectory::Nominal;

/// Why a recording is not a certified run of a hybrid task.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ImportError {
    #[error("the recording's x0 has {x0} values and its rows {m_rec} inputs; the plant has n = {n}, m = {m}")]
    Shape {
        x0: usize,
        m_rec: usize,
        n: usize,
        m: usize,
    },
    #[error("the recording has no rows")]
    Empty,
    #[error(
        "the automaton's edges are forced: the recording has no `location` column, and reference inputs \
         alone do not say when the controller switches (give each row's location, as `play` writes it)"
    )]
    Forced,
    #[error("row {row} (t = {t:.2} s): `{name}` is not a location of the automaton (its locations: {known})")]
    UnknownLocation {
        row: usize,
        t: f64,
        name: String,
        known: String,
    },
    #[error("the run starts in {found}; the task's initial location is {initial}")]
    NotInitial { found: String, initial: String },
    #[error(
        "row {row} (t = {t:.2} s): the run switches {from} → {to}, but no forced edge leads from {from} \
         to {to}"
    )]
    NoForcedEdge {
        row: usize,
        t: f64,
        from: String,
        to: String,
    },
    #[error(
        "the task is a formula, judged over the whole horizon of {steps} samples; the recording has \
         {rows} rows, and its tables must cover the horizon"
    )]
    ShortForFormula { rows: usize, steps: usize },
    #[error(
        "row {row} (t = {t:.2} s): the recording's `location` is {recorded}; replayed on the automaton \
         (whose edges are internal: the plant switches), the run is in {replayed} there"
    )]
    LocationMismatch {
        row: usize,
        t: f64,
        recorded: String,
        replayed: String,
    },
    #[error(
        "segment {segment} ({from}): the run never takes the path's edge {edge} ({from} → {to}); it stays \
         in {from} for the {rows} samples it has from t = {t:.2} s on"
    )]
    NoSwitch {
        segment: usize,
        edge: usize,
        from: String,
        to: String,
        rows: usize,
        t: f64,
    },
    #[error(
        "segment {segment} ({from}): at t = {t:.2} s (sample {k}) the run takes edge {taken} ({from} → \
         {taken_to}); the path leaves {from} by edge {edge} (→ {to})"
    )]
    WrongEdge {
        segment: usize,
        k: usize,
        t: f64,
        from: String,
        taken: usize,
        taken_to: String,
        edge: usize,
        to: String,
    },
    #[error(
        "segment {segment}: in the period from t = {t:.2} s (sample {k}) the run switches {events} times \
         and ends in {ended}, not in {to}; a segment is the samples in one location"
    )]
    Chatter {
        segment: usize,
        k: usize,
        t: f64,
        events: usize,
        ended: String,
        to: String,
    },
    #[error("segment {segment} ({loc}): the run ends at its switch, at t = {t:.2} s: the segment has no samples")]
    EndsAtSwitch { segment: usize, loc: String, t: f64 },
    #[error("segment {segment}: the exact flow cannot be replayed at t = {t:.2} s (sample {k}): {reason}")]
    Flow {
        segment: usize,
        k: usize,
        t: f64,
        reason: String,
    },
    #[error("the run is not one the internal-switching certificate takes: {0}")]
    Certificate(String),
    #[error("refused: {0}")]
    Refused(String),
}

/// A recording replayed and split (module doc).
#[derive(Clone, Debug)]
pub struct Replay {
    /// One nominal per segment of the task's path (shipped: f32 start and rows), every one but the last
    /// extended past its event to the recording's end ([`Replay::extended`] cuts them).
    pub nominals: Vec<Nominal>,
    /// The recording's sample at which each segment starts (κᵢ; 0 for the first).
    pub starts: Vec<usize>,
}

impl Replay {
    /// The segments with every extended one cut at its first sample `depth` deep (Euclidean) in its exit
    /// guard; `None` if one never gets that deep.
    pub fn extended(&self, task: &HybridTask, depth: f64) -> Option<Vec<Nominal>> {
        self.nominals
            .iter()
            .enumerate()
            .map(|(i, nom)| match task.edges.get(i) {
                Some(&e) => {
                    let guard = &task.plant.edges()[e].guard;
                    let k = nom.x.iter().position(|x| guard.margin(x) <= -depth)?;
                    Some(truncate(nom, k.max(1)))
                }
                None => Some(nom.clone()),
            })
            .collect()
    }
}

impl Replay {
    /// The same split with every later segment restarted at the centre of the landings of runs near the
    /// previous segment's nominal (`plan_run`'s start, rounded to f32), its rows unchanged; `None` if a
    /// segment's nominal then does not switch by the path's edge.
    pub fn centred(&self, task: &HybridTask) -> Option<Replay> {
        let mut nominals: Vec<Nominal> = Vec::with_capacity(self.nominals.len());
        for (i, nom) in self.nominals.iter().enumerate() {
            let seg = match nominals.last() {
                None => nom.clone(),
                Some(prev) => {
                    let l = super::landing(task, task.path[i - 1], prev, task.edges[i - 1])?;
                    let x = super::f32_start(&l);
                    shipped_nominal(task, task.path[i], &x, &nom.v)
                }
            };
            nominals.push(seg);
        }
        Some(Replay {
            nominals,
            starts: self.starts.clone(),
        })
    }
}

/// The recording on the automaton (module doc): the segments, or why the run does not follow the path.
pub fn replay(task: &HybridTask, rec: &Recording) -> Result<Replay, ImportError> {
    if task.forced {
        return Err(ImportError::Forced);
    }
    let plant = &task.plant;
    let (n, m) = (crate::model::Plant::n(plant), crate::model::Plant::m(plant));
    if rec.x0.len() != n || rec.v.iter().any(|r| r.len() != m) {
        return Err(ImportError::Shape {
            x0: rec.x0.len(),
            m_rec: rec.v.iter().map(Vec::len).find(|&l| l != m).unwrap_or(m),
            n,
            m,
        });
    }
    if rec.v.is_empty() {
        return Err(ImportError::Empty);
    }
    let h = plant.period();
    let name = |l: Location| plant.modes()[l].name.clone();
    let mut x = super::f32_start(&rec.x0);
    let mut k0 = 0usize;
    let (mut nominals, mut starts) = (Vec::new(), Vec::new());
    for (i, &loc) in task.path.iter().enumerate() {
        if k0 >= rec.v.len() {
            return Err(ImportError::EndsAtSwitch {
                segment: i.saturating_sub(1),
                loc: name(task.path[i.saturating_sub(1)]),
                t: k0 as f64 * h,
            });
        }
        let nom = shipped_nominal(task, loc, &x, &rec.v[k0..]);
        starts.push(k0);
        let Some(&edge) = task.edges.get(i) else {
            nominals.push(nom);
            break;
        };
        let to = plant.edges()[edge].to;
        let mut landed = None;
        for k in 0..nom.steps() {
            let flow = |reason: String| ImportError::Flow {
                segment: i,
                k: k0 + k,
                t: (k0 + k) as f64 * h,
                reason,
            };
            let step = plant
                .flow(loc, &nom.x[k], &nom.u[k])
                .map_err(|e| flow(e.to_string()))?;
            let Some(ev) = step.events.first() else {
                continue;
            };
            if ev.edge != edge {
                return Err(ImportError::WrongEdge {
                    segment: i,
                    k: k0 + k,
                    t: (k0 + k) as f64 * h + ev.time,
                    from: name(loc),
                    taken: ev.edge,
                    taken_to: name(plant.edges()[ev.edge].to),
                    edge,
                    to: name(to),
                });
            }
            if step.loc != to {
                return Err(ImportError::Chatter {
                    segment: i,
                    k: k0 + k,
                    t: (k0 + k) as f64 * h,
                    events: step.events.len(),
                    ended: name(step.loc),
                    to: name(to),
                });
            }
            landed = Some((k, step.x));
            break;
        }
        let Some((ke, xl)) = landed else {
            return Err(ImportError::NoSwitch {
                segment: i,
                edge,
                from: name(loc),
                to: name(to),
                rows: nom.steps(),
                t: k0 as f64 * h,
            });
        };
        nominals.push(nom);
        // f32-representable: the image stores the next segment's start.
        x = super::f32_start(&xl);
        k0 += ke + 1;
    }
    let replay = Replay { nominals, starts };
    if let Some(names) = &rec.locations {
        check_locations(task, names, &replay)?;
    }
    Ok(replay)
}

/// With internal switching a recording's [`crate::trajectory::csv::LOCATION`] column (a run `simulate`
/// wrote has one) says where the plant was; up to the last segment's first sample in Goal (after which
/// the certificate judges nothing, and the plant may switch on) it must be where the replay puts it: row
/// κ in the path's location of the segment the replay starts at or before κ.
fn check_locations(
    task: &HybridTask,
    names: &[String],
    replay: &Replay,
) -> Result<(), ImportError> {
    let modes = task.plant.modes();
    let starts = &replay.starts;
    let last = starts.last().copied().unwrap_or(0);
    let goal = replay
        .nominals
        .last()
        .and_then(|nom| nom.x.iter().position(|x| task.property.goal.contains(x)));
    let judged = goal.map_or(names.len(), |k| (last + k + 1).min(names.len()));
    for (row, name) in names.iter().enumerate().take(judged) {
        let seg = starts.iter().rposition(|&s| s <= row).unwrap_or(0);
        let replayed = &modes[task.path[seg]].name;
        if name != replayed {
            return Err(ImportError::LocationMismatch {
                row,
                t: row as f64 * task.plant.period(),
                recorded: crate::text::excerpt(name),
                replayed: replayed.clone(),
            });
        }
    }
    Ok(())
}

/// A recording certified as a run of the task's path (module doc): the run when its certificate is
/// positive, else why not (the replay's reason, or per segment what binds and by how much).
pub fn certify_recording(task: &HybridTask, rec: &Recording) -> Result<HybridRun, ImportError> {
    if task.forced {
        return certify_forced_recording(task, rec);
    }
    let r = replay(task, rec)?;
    let centred = r.centred(task);
    let mut candidates: Vec<Vec<Nominal>> = Vec::new();
    for split in std::iter::once(&r).chain(centred.as_ref()) {
        candidates.extend(
            super::GUARD_DEPTHS
                .iter()
                .filter_map(|&d| split.extended(task, d)),
        );
    }
    if candidates.is_empty() {
        candidates.push(r.nominals);
    }
    // The largest δ; among refusals the reason of the replayed landing's shallowest extension.
    let mut best: Option<HybridRun> = None;
    for nominals in candidates {
        let certificate = certify_run(task, &nominals).map_err(ImportError::Certificate)?;
        if best
            .as_ref()
            .is_none_or(|b| certificate.delta() > b.delta())
        {
            best = Some(HybridRun {
                locations: task.path.clone(),
                nominals,
                certificate,
            });
        }
    }
    match best {
        Some(run) if run.certificate.is_certified() => Ok(run),
        Some(run) => Err(ImportError::Refused(refusal(
            task,
            &run.locations,
            &run.certificate,
        ))),
        None => Err(ImportError::Empty),
    }
}

/// A forced-switching recording certified (module doc, "Forced switching").
fn certify_forced_recording(task: &HybridTask, rec: &Recording) -> Result<HybridRun, ImportError> {
    let plant = &task.plant;
    let (n, m) = (crate::model::Plant::n(plant), crate::model::Plant::m(plant));
    if rec.x0.len() != n || rec.v.iter().any(|r| r.len() != m) {
        return Err(ImportError::Shape {
            x0: rec.x0.len(),
            m_rec: rec.v.first().map_or(0, Vec::len),
            n,
            m,
        });
    }
    if rec.v.is_empty() {
        return Err(ImportError::Empty);
    }
    // A formula's windows past the run's end would be judged on nothing (Def 4.18 is over all of T).
    if task.formula.is_some() && rec.v.len() < task.steps {
        return Err(ImportError::ShortForFormula {
            rows: rec.v.len(),
            steps: task.steps,
        });
    }
    let names = rec.locations.as_ref().ok_or(ImportError::Forced)?;
    let modes = plant.modes();
    let h = plant.period();
    // Each row's location, then the segments: (location, first row, rows).
    let mut rows_loc = Vec::with_capacity(names.len());
    for (row, name) in names.iter().enumerate() {
        let l = modes
            .iter()
            .position(|md| &md.name == name)
            .ok_or_else(|| ImportError::UnknownLocation {
                row,
                t: row as f64 * h,
                name: name.clone(),
                known: modes
                    .iter()
                    .map(|md| md.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
            })?;
        rows_loc.push(l);
    }
    if rows_loc[0] != task.initial {
        return Err(ImportError::NotInitial {
            found: modes[rows_loc[0]].name.clone(),
            initial: modes[task.initial].name.clone(),
        });
    }
    let (mut locations, mut edges, mut starts) = (vec![rows_loc[0]], Vec::new(), vec![0usize]);
    for row in 1..rows_loc.len() {
        let (from, to) = (rows_loc[row - 1], rows_loc[row]);
        if from == to {
            continue;
        }
        let e = plant
            .edges()
            .iter()
            .position(|e| {
                e.from == from && e.to == to && e.kind == crate::model::hybrid::EdgeKind::Forced
            })
            .ok_or_else(|| ImportError::NoForcedEdge {
                row,
                t: row as f64 * h,
                from: modes[from].name.clone(),
                to: modes[to].name.clone(),
            })?;
        locations.push(to);
        edges.push(e);
        starts.push(row);
    }
    starts.push(rec.v.len());
    // The segments as `plan_forced` simulates them: the f32 start, each from the previous one's end.
    let mut nominals = Vec::with_capacity(locations.len());
    let mut start = super::f32_start(&rec.x0);
    for (i, &l) in locations.iter().enumerate() {
        let nom = shipped_nominal(task, l, &start, &rec.v[starts[i]..starts[i + 1]]);
        start = nom.x.last().cloned().unwrap_or_default();
        nominals.push(nom);
    }
    let certificate = super::forced::certify_run(task, &locations, &edges, &nominals)
        .map_err(ImportError::Certificate)?;
    if !certificate.is_certified() {
        return Err(ImportError::Refused(refusal(
            task,
            &locations,
            &certificate,
        )));
    }
    Ok(HybridRun {
        nominals,
        locations,
        certificate,
    })
}

/// Why a run's certificate is not positive: the segment that fails first when the certificate is built
/// backwards (the last one with δ = 0; earlier ones fail because it does), what binds it, and Theorem
/// 4.7's parts over its kept rows with their samples.
pub fn refusal(task: &HybridTask, locations: &[Location], c: &InternalCertificate) -> String {
    let h = task.plant.period();
    let cause = c
        .segments
        .iter()
        .rposition(|s| s.delta <= 0.0 || s.delta.is_nan())
        .unwrap_or(0);
    let Some(s) = c.segments.get(cause) else {
        return "the run has no segments".into();
    };
    let loc = locations.get(cause).copied().unwrap_or(0);
    let b = &s.base;
    let at = |k: usize| format!("t = {:.2} s", k as f64 * h);
    let mut parts = vec![
        format!(
            "δ_Unsafe = {:.3e} at {} (between samples, the run's other guards and its invariant counted)",
            b.delta_unsafe_intersample,
            at(b.k_unsafe)
        ),
        format!("δ_Input = {:.3e} at {}", b.delta_input, at(b.k_input)),
    ];
    if s.exit.is_none() {
        parts.insert(
            0,
            format!("δ_Goal = {:.3e} at {}", b.delta_goal, at(b.k_star)),
        );
    }
    parts.push(format!("r_crit = {:.3e}", b.r_crit));
    let later = if cause + 1 < c.segments.len() {
        format!(
            "; the next segment's δ is {:.3e}",
            c.segments[cause + 1].delta
        )
    } else {
        String::new()
    };
    format!(
        "segment {cause} ({}) certifies no radius, limited by {}: {}{later}",
        task.plant.modes()[loc].name,
        s.binding,
        parts.join(", ")
    )
}

/// What an accepted run's δ is limited by, per segment (for messages).
pub fn bindings(task: &HybridTask, locations: &[Location], c: &InternalCertificate) -> String {
    c.segments
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let loc = locations.get(i).copied().unwrap_or(0);
            format!(
                "segment {i} ({}): δ = {:.3e}, {}",
                task.plant.modes()[loc].name,
                s.delta,
                s.binding
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}
