//! Tracking feedback K and quadratic control autobisimulation function (CAF) V(x) = xᵀPx: the LMIs of
//! §3.1 (3.8) and §3.1.4 (3.66–3.67), solved with clarabel's PSD cone.
