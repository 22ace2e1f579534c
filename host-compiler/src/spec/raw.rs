//! The spec file exactly as written: serde structs over TOML with a span on every value that validation
//! may need to point at. Nothing here is checked beyond TOML types and key names (unknown keys are
//! rejected by serde with their span); `spec::validate` turns these into a `Problem`.

use serde::Deserialize;
use toml::Spanned;

/// A number with its span.
pub(crate) type RawF = Spanned<f64>;
/// A vector (TOML array of numbers) with spans on the whole and on each entry.
pub(crate) type RawVec = Spanned<Vec<RawF>>;
/// A matrix as an array of rows, with spans on the whole, on each row and on each entry.
pub(crate) type RawMat = Spanned<Vec<RawVec>>;

/// Top level of a task spec. `P` is the `[plant]` table: [`RawPlant`] for linear and hybrid plants,
/// `super::nonlinear::RawFlPlant` for a plant with a `class`.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSpec<P = RawPlant> {
    pub name: Option<Spanned<String>>,
    /// Read wide so that out-of-range values get a range error rather than a type error.
    pub seed: Spanned<i128>,
    pub horizon: Spanned<f64>,
    pub plant: Spanned<P>,
    pub init: Spanned<RawSet>,
    pub goal: Spanned<RawSet>,
    #[serde(default, rename = "unsafe")]
    pub unsafe_sets: Vec<Spanned<RawSet>>,
    pub input: Spanned<RawInput>,
    pub synthesis: Option<Spanned<RawSynthesis>>,
    pub mtl: Option<Spanned<RawMtl>>,
    #[serde(default)]
    pub sets: Pairs<Spanned<String>, Spanned<RawSet>>,
}

/// A TOML table read as its (key, value) pairs in file order.
#[derive(Debug)]
pub(crate) struct Pairs<K, V>(pub Vec<(K, V)>);

impl<K, V> Default for Pairs<K, V> {
    fn default() -> Self {
        Pairs(Vec::new())
    }
}

impl<'de, K: Deserialize<'de>, V: Deserialize<'de>> Deserialize<'de> for Pairs<K, V> {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visit<K, V>(std::marker::PhantomData<(K, V)>);
        impl<'de, K: Deserialize<'de>, V: Deserialize<'de>> serde::de::Visitor<'de> for Visit<K, V> {
            type Value = Pairs<K, V>;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a table of named sets")
            }
            fn visit_map<M: serde::de::MapAccess<'de>>(
                self,
                mut m: M,
            ) -> Result<Self::Value, M::Error> {
                let mut v = Vec::new();
                while let Some((k, x)) = m.next_entry()? {
                    v.push((k, x));
                }
                Ok(Pairs(v))
            }
        }
        d.deserialize_map(Visit(std::marker::PhantomData))
    }
}

/// Whether the plant is stated in continuous or discrete time.
#[derive(Deserialize, Debug, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub(crate) enum RawTime {
    Continuous,
    Discrete,
}

/// `[plant]`.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawPlant {
    pub time: Spanned<RawTime>,
    /// Required for a plant with one location; a hybrid plant gives them per location.
    pub A: Option<RawMat>,
    pub B: Option<RawMat>,
    /// Continuous-time affine term.
    pub c: Option<RawVec>,
    /// Discrete-time affine term.
    pub g: Option<RawVec>,
    pub period: Spanned<f64>,
    /// Output map.
    pub C: Option<RawMat>,
    /// A hybrid automaton ([`super::hybrid`]): the location Init is in, the locations and the edges.
    pub initial: Option<Spanned<String>>,
    #[serde(default)]
    pub location: Vec<Spanned<super::hybrid::RawLocation>>,
    #[serde(default)]
    pub edge: Vec<Spanned<super::hybrid::RawEdge>>,
}

/// A set table: `[goal]`, `[init]`, `[[unsafe]]`, `[sets.<name>]`. Which keys are required depends on
/// `kind`; validation checks that.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSet {
    pub kind: Spanned<String>,
    pub center: Option<RawVec>,
    pub Q: Option<RawMat>,
    pub radius: Option<RawF>,
    pub A: Option<RawMat>,
    pub b: Option<RawVec>,
    pub lo: Option<RawVec>,
    pub hi: Option<RawVec>,
    pub coords: Option<Spanned<toml::Value>>,
}

/// `[input]`.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawInput {
    pub kind: Spanned<String>,
    pub lo: Option<RawVec>,
    pub hi: Option<RawVec>,
    pub center: Option<RawVec>,
    pub radius: Option<RawF>,
    /// The fallback input (m values), optional.
    pub fallback: Option<RawVec>,
}

/// `[synthesis]`: every key optional.
#[derive(Deserialize, Debug, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSynthesis {
    pub mode: Option<Spanned<String>>,
    pub confidence: Option<RawF>,
    pub coverage_target: Option<RawF>,
    pub coverage_tolerance: Option<RawF>,
    pub max_trajectories: Option<Spanned<i128>>,
    pub max_iterations: Option<Spanned<i128>>,
    pub sigma_margin: Option<RawF>,
    pub min_robustness: Option<RawF>,
    pub reference_hold: Option<Spanned<i128>>,
    pub terminal: Option<Spanned<String>>,
}

/// `[mtl]`.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMtl {
    pub formula: Spanned<String>,
}

/// A standalone named-sets file: only `[sets.<name>]` tables.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawSetsFile {
    #[serde(default)]
    pub sets: Pairs<Spanned<String>, Spanned<RawSet>>,
}
