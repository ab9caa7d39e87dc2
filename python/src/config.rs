//! The sensor config from Python: `None` (the paper's parameters), TOML
//! text (`str`), a TOML file (`os.PathLike`, e.g. `pathlib.Path`), or a
//! `dict` of the same tables. All end in [`Params`] with its range checks,
//! exactly as `dexitac analyze --config` loads a file.

use std::path::{Path, PathBuf};

use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};

use dexitac_tactile::area::{AreaSpec, MaskImage};
use dexitac_tactile::params::{Params, ParamsError};

/// Reads the `config` argument of `Sensor.from_rest` and friends.
pub fn params(config: Option<&Bound<'_, PyAny>>) -> PyResult<Params> {
    let Some(config) = config.filter(|c| !c.is_none()) else {
        return Ok(Params::default());
    };
    if let Ok(text) = config.cast::<PyString>() {
        let text = text.to_cow()?;
        let params = Params::from_toml_str(&text).map_err(|e| {
            let hint = if looks_like_path(&text) {
                " (a str is TOML text; pass pathlib.Path(...) for a file)"
            } else {
                ""
            };
            PyValueError::new_err(format!("{e}{hint}"))
        })?;
        return with_mask(params, Path::new("."));
    }
    if let Ok(dict) = config.cast::<PyDict>() {
        let table = table(dict, "config")?;
        let params: Params = toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| PyValueError::new_err(format!("invalid config: {e}")))?;
        params.validate().map_err(value_error)?;
        return with_mask(params, Path::new("."));
    }
    if let Ok(path) = config.extract::<PathBuf>() {
        let text = std::fs::read_to_string(&path).map_err(|e| {
            PyOSError::new_err(format!("cannot read config {}: {e}", path.display()))
        })?;
        let params = Params::from_toml_str(&text)
            .map_err(|e| PyValueError::new_err(format!("config {}: {e}", path.display())))?;
        return with_mask(params, path.parent().unwrap_or(Path::new(".")));
    }
    Err(PyValueError::new_err(format!(
        "config must be None, TOML text (str), a file (pathlib.Path) or a dict, got {}",
        config
            .get_type()
            .name()
            .map_or_else(|_| "?".to_string(), |n| n.to_string())
    )))
}

fn looks_like_path(text: &str) -> bool {
    let t = text.trim();
    !t.contains('\n') && (t.ends_with(".toml") || t.contains('/'))
}

/// Decodes the `[area] shape = "mask"` image, as `load_sensor_config` of the
/// CLI does.
fn with_mask(mut params: Params, dir: &Path) -> PyResult<Params> {
    if let AreaSpec::Mask { path } = &params.area {
        let file = dir.join(path);
        let img = image::open(&file).map_err(|e| match e {
            image::ImageError::IoError(io) => {
                PyOSError::new_err(format!("sensing-area mask {}: {io}", file.display()))
            }
            other => {
                PyValueError::new_err(format!("sensing-area mask {}: {other}", file.display()))
            }
        })?;
        let img = img.to_luma8();
        params.area_mask = Some(MaskImage {
            width: img.width() as usize,
            height: img.height() as usize,
            inside: img.into_raw().into_iter().map(|v| v > 0).collect(),
        });
    }
    Ok(params)
}

/// A Python dict -> a TOML table (str keys; bool, int, float, str, list,
/// tuple and dict values).
fn table(dict: &Bound<'_, PyDict>, at: &str) -> PyResult<toml::Table> {
    let mut out = toml::Table::new();
    for (k, v) in dict.iter() {
        let key: String = k.extract().map_err(|_| {
            PyValueError::new_err(format!("config keys must be str ({at} has {k})"))
        })?;
        let here = format!("{at}.{key}");
        out.insert(key, value(&v, &here)?);
    }
    Ok(out)
}

fn value(v: &Bound<'_, PyAny>, at: &str) -> PyResult<toml::Value> {
    // bool first: a Python bool is also an int.
    if let Ok(b) = v.cast::<PyBool>() {
        return Ok(toml::Value::Boolean(b.is_true()));
    }
    if v.cast::<PyInt>().is_ok() {
        let i: i64 = v
            .extract()
            .map_err(|_| PyValueError::new_err(format!("{at}: integer out of range")))?;
        return Ok(toml::Value::Integer(i));
    }
    if let Ok(f) = v.cast::<PyFloat>() {
        return Ok(toml::Value::Float(f.value()));
    }
    if let Ok(s) = v.cast::<PyString>() {
        return Ok(toml::Value::String(s.to_cow()?.into_owned()));
    }
    if let Ok(d) = v.cast::<PyDict>() {
        return Ok(toml::Value::Table(table(d, at)?));
    }
    if v.cast::<PyList>().is_ok() || v.cast::<PyTuple>().is_ok() {
        let mut items = Vec::new();
        for (k, item) in v.try_iter()?.enumerate() {
            items.push(value(&item?, &format!("{at}[{k}]"))?);
        }
        return Ok(toml::Value::Array(items));
    }
    // numpy scalars and other numbers: as float or int.
    if let Ok(i) = v.extract::<i64>() {
        return Ok(toml::Value::Integer(i));
    }
    if let Ok(f) = v.extract::<f64>() {
        return Ok(toml::Value::Float(f));
    }
    Err(PyValueError::new_err(format!(
        "{at}: {} is not a TOML value (bool, int, float, str, list or dict)",
        v.get_type()
            .name()
            .map_or_else(|_| "?".to_string(), |n| n.to_string())
    )))
}

fn value_error(e: ParamsError) -> PyErr {
    PyValueError::new_err(e.to_string())
}
