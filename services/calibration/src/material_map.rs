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

/// The inverse of [`params_to_map`], validated; `field` names the map in errors.
pub fn params_from_map(
    map: &std::collections::BTreeMap<String, f32>,
    field: &str,
) -> Result<PrincipledParams<f32>, String> {
    if let Some(unknown) = map
        .keys()
        .find(|k| !PrincipledParams::<f32>::NAMES.contains(&k.as_str()))
    {
        return Err(format!("{field}: unknown parameter {unknown:?}"));
    }
    let mut values = [0f32; glint_render::bsdf::PARAMETER_COUNT];
    for (v, name) in values.iter_mut().zip(PrincipledParams::<f32>::NAMES) {
        *v = *map
            .get(name)
            .ok_or_else(|| format!("{field}: missing parameter {name:?}"))?;
    }
    PrincipledParams::from_array(values)
        .validated()
        .map_err(|e| format!("{field}: {e}"))
}
