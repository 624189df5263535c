//! The MPC's ground-effect surface, from `[model] ground_effect` of the MPC
//! settings: none (the nominal model), the plant's documented default
//! surface, or `[effects.ground_effect]` of a plant file (the format of
//! `config/plant.toml` and of the `fitted_effects.toml` that `atmo-sim
//! explain` writes). Start-up only.

use std::path::Path;
use std::sync::Arc;

use atmo_core::ground_effect::{GroundEffect, GroundEffectConfig, ThrustGainSurface};
use atmo_mpc::settings::GroundEffectSource;

use crate::error::{FlightError, Result};

/// A shared surface, as the MPC takes it.
pub type Surface = Arc<dyn ThrustGainSurface>;

/// The surface `source` names, loaded and checked (a file is read here).
pub fn ground_surface(source: &GroundEffectSource) -> Result<Option<Surface>> {
    Ok(match source {
        GroundEffectSource::None => None,
        GroundEffectSource::PlantDefault => Some(Arc::new(GroundEffect::default_surface())),
        GroundEffectSource::File(path) => {
            let text = atmo_core::config_file::read_config_file(path)
                .map_err(|e| FlightError::Setup(format!("model.ground_effect: {e}")))?;
            Some(surface_from_text(&text, path)?)
        }
    })
}

/// The enabled `[effects.ground_effect]` of a plant file's `text` (read
/// from `source`, named in errors).
pub fn surface_from_text(text: &str, source: &Path) -> Result<Surface> {
    let config = GroundEffectConfig::from_plant_file(text, source)
        .map_err(|e| FlightError::Setup(format!("model.ground_effect: {e}")))?;
    let Some(config) = config else {
        return Err(FlightError::Setup(format!(
            "model.ground_effect: {} has no enabled [effects.ground_effect]",
            source.display()
        )));
    };
    Ok(Arc::new(GroundEffect::new(&config)))
}
