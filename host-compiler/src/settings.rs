//! The settings convention (DESIGN §7, after clarabel's `DefaultSettingsBuilder`): a settings struct has a
//! `Default` whose every value is documented on its field, and a builder (`XSettings::builder()`, starting
//! from the defaults) whose `build()` checks the ranges documented on the fields and refuses a value with an
//! error that names the field, the value and the rule.
//!
//! This module holds the pieces shared by the settings of the optimisers, the trajectory generator, the PWA
//! learner and the geometry: the error [`SettingError`], the range checks, and [`settings_builder!`], which
//! writes a builder from a struct's field list (each struct writes its own `validate`). The CAF and synthesis
//! settings ([`crate::caf::CafSettings`], [`crate::spec::SynthesisSettings`]) follow the same convention
//! with the error types of their modules (`CafError::Settings`, `spec::SettingsError`).

// Negated comparisons (`!(x > 0.0)`) are deliberate: they reject NaN as well.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

/// A setting outside its documented range.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[error("{settings}.{field} = {value}: {rule}")]
pub struct SettingError {
    /// The settings struct, e.g. `"PwaSettings"`.
    pub settings: &'static str,
    /// The field.
    pub field: &'static str,
    /// The refused value (integers as f64).
    pub value: f64,
    /// The documented rule it breaks.
    pub rule: &'static str,
}

/// Range checks of one settings struct: each returns the [`SettingError`] naming the field.
pub(crate) struct Check(pub &'static str);

impl Check {
    fn err(&self, field: &'static str, value: f64, rule: &'static str) -> Result<(), SettingError> {
        Err(SettingError {
            settings: self.0,
            field,
            value,
            rule,
        })
    }

    /// `ok`, or the error with `rule`.
    pub fn rule(
        &self,
        field: &'static str,
        value: f64,
        ok: bool,
        rule: &'static str,
    ) -> Result<(), SettingError> {
        if ok {
            Ok(())
        } else {
            self.err(field, value, rule)
        }
    }

    /// Finite and > 0.
    pub fn positive(&self, field: &'static str, v: f64) -> Result<(), SettingError> {
        self.rule(field, v, v.is_finite() && v > 0.0, "must be finite and > 0")
    }

    /// Finite and ≥ 0.
    pub fn non_negative(&self, field: &'static str, v: f64) -> Result<(), SettingError> {
        self.rule(
            field,
            v,
            v.is_finite() && v >= 0.0,
            "must be finite and ≥ 0",
        )
    }

    /// In the open interval (0, 1).
    pub fn open_unit(&self, field: &'static str, v: f64) -> Result<(), SettingError> {
        self.rule(field, v, v > 0.0 && v < 1.0, "must lie in (0, 1)")
    }

    /// At least 1.
    pub fn at_least_one(&self, field: &'static str, v: usize) -> Result<(), SettingError> {
        self.rule(field, v as f64, v >= 1, "must be at least 1")
    }
}

/// Writes `$builder` for the settings struct `$settings` (which has `Default` and
/// `fn validate(&self) -> Result<(), SettingError>`): `$settings::builder()`, one setter per listed field,
/// and `build()`, which validates.
macro_rules! settings_builder {
    ($settings:ident, $builder:ident { $($field:ident: $ty:ty),* $(,)? }) => {
        #[doc = concat!("Builder for [`", stringify!($settings), "`], starting from its defaults; [`",
            stringify!($builder), "::build`] checks the documented ranges.")]
        #[derive(Clone, Debug, Default)]
        pub struct $builder {
            s: $settings,
        }

        impl $builder {
            $(
                #[doc = concat!("See [`", stringify!($settings), "::", stringify!($field), "`].")]
                pub fn $field(mut self, v: $ty) -> Self {
                    self.s.$field = v;
                    self
                }
            )*

            /// The settings, if every field is in its documented range.
            pub fn build(self) -> Result<$settings, $crate::settings::SettingError> {
                self.s.validate()?;
                Ok(self.s)
            }
        }

        impl $settings {
            /// A builder starting from the defaults.
            pub fn builder() -> $builder {
                $builder::default()
            }
            /// A builder starting from these settings (to change some fields and check them again).
            pub fn to_builder(self) -> $builder {
                $builder { s: self }
            }
        }
    };
}
pub(crate) use settings_builder;
