//! What the base config of a sequence may hold: everything that acts in each frame's own
//! raster frame (hysteresis, coupling, vibration, noise, tip, feature shape) or follows the
//! lattice (modulations); not drift (that belongs to `[sequence]`) and not sample features
//! that would have to be moved and turned into each frame (steps, strain, a second
//! domain, defects).

use crate::SimulationError;
use crate::config::SimulationConfig;
use crate::effects::EffectConfig;
use crate::error::invalid;

/// Refuses base-config content a sequence cannot carry; the error names the field.
pub(crate) fn check_base(base: &SimulationConfig) -> Result<(), SimulationError> {
    for (index, effect) in base.effects.iter().enumerate() {
        if let Some(reason) = refusal(effect) {
            return Err(invalid(
                format!("effects[{index}]"),
                format!(
                    "a '{}' effect is not allowed in a sequence's base config: {reason}",
                    effect.kind()
                ),
            ));
        }
    }
    check_surface(base)
}

/// Why `effect` cannot be part of a sequence's base config, if it cannot.
fn refusal(effect: &EffectConfig) -> Option<&'static str> {
    const DRIFT: &str = "drift and creep belong to the session (sequence.drift, \
                         sequence.initial_creep, sequence.moves[].creep), continuous over \
                         the frames";
    match effect {
        EffectConfig::ThermalDrift(_)
        | EffectConfig::Creep(_)
        | EffectConfig::ExponentialCreep(_)
        | EffectConfig::LineDrift(_)
        | EffectConfig::SessionDrift(_) => Some(DRIFT),
        EffectConfig::TipChange(_) => Some(
            "a tip change at a frame time would recur in every frame and be undone at \
             every frame start",
        ),
        _ => None,
    }
}

/// Steps, strain, a second domain and placed defects would have to be placed per frame
/// (vacancies chosen by fraction belong to lattice sites and follow the lattice).
fn check_surface(base: &SimulationConfig) -> Result<(), SimulationError> {
    let surface = &base.surface;
    let defects = &surface.defects;
    let refused = [
        ("surface.steps", !surface.steps.is_empty()),
        ("surface.strain", !surface.strain.is_empty()),
        ("surface.second_domain", surface.second_domain.is_some()),
        (
            "surface.defects.vacancy_positions_m",
            !defects.vacancy_positions_m.is_empty(),
        ),
        ("surface.defects.adatom_count", defects.adatom_count != 0),
        (
            "surface.defects.adatom_positions_m",
            !defects.adatom_positions_m.is_empty(),
        ),
    ];
    match refused.into_iter().find(|(_, present)| *present) {
        Some((field, _)) => Err(invalid(
            field,
            "is not supported in a sequence's base config: every frame shows the same \
             lattice, turned and shifted into its own frame, and this part of the surface \
             is not transformed per frame",
        )),
        None => Ok(()),
    }
}
