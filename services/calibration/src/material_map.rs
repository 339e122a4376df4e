//! Principled parameters as name → value maps, the form material files and the calibration's
//! JSON outputs use (every name of [`PrincipledParams::NAMES`]).

use glint_render::bsdf::PrincipledParams;

/// Principled parameters as a name → value map (every name of [`PrincipledParams::NAMES`]).
pub fn params_to_map(p: &PrincipledParams<f32>) -> std::collections::BTreeMap<String, f32> {
    PrincipledParams::<f32>::NAMES
        .iter()
        .zip(p.to_array())
        .map(|(n, v)| (n.to_string(), v))
        .collect()
}

/// Why a parameter map is not a material.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MaterialMapError {
    /// The map has a name that is not one of [`PrincipledParams::NAMES`] (a typo, or another
    /// format's key); remove or rename it.
    #[error("{field}: unknown parameter {name:?}")]
    Unknown {
        /// The map's name, as given to [`params_from_map`].
        field: String,
        /// The unknown name.
        name: String,
    },
    /// A parameter of [`PrincipledParams::NAMES`] is absent: every one must be given.
    #[error("{field}: missing parameter {name:?}")]
    Missing {
        /// The map's name, as given to [`params_from_map`].
        field: String,
        /// The missing parameter.
        name: &'static str,
    },
    /// A value is outside its valid range (every principled parameter lies in [0, 1]).
    #[error("{field}: {source}")]
    OutOfRange {
        /// The map's name, as given to [`params_from_map`].
        field: String,
        /// Which parameter, and its value.
        #[source]
        source: glint_render::bsdf::InvalidParameter,
    },
}

/// The inverse of [`params_to_map`], validated; `field` names the map in errors.
pub fn params_from_map(
    map: &std::collections::BTreeMap<String, f32>,
    field: &str,
) -> Result<PrincipledParams<f32>, MaterialMapError> {
    if let Some(unknown) = map
        .keys()
        .find(|k| !PrincipledParams::<f32>::NAMES.contains(&k.as_str()))
    {
        return Err(MaterialMapError::Unknown {
            field: field.into(),
            name: unknown.clone(),
        });
    }
    let mut values = [0f32; glint_render::bsdf::PARAMETER_COUNT];
    for (v, name) in values.iter_mut().zip(PrincipledParams::<f32>::NAMES) {
        *v = *map.get(name).ok_or_else(|| MaterialMapError::Missing {
            field: field.into(),
            name,
        })?;
    }
    PrincipledParams::from_array(values)
        .validated()
        .map_err(|source| MaterialMapError::OutOfRange {
            field: field.into(),
            source,
        })
}
