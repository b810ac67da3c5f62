//! `meb.Luminaire`: a luminaire on a serial port (or the virtual one of `meb device
//! emulate`) through [`meb_device::DeviceClient`], the client of `meb device`.

use crate::errors::meb_error;
use crate::json::to_python;
use crate::refusals::warn;
use meb_device::discovery::list_ports;
use meb_device::settings::{self, DepthRequest, SettingsRequest, Spelling};
use meb_device::{DeviceClient, Timeouts};
use protocol::carriers::MAX_LEDS;
use protocol::config::LuminaireConfig;
use protocol::flicker;
use protocol::wire::SaveOutcome;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::path::PathBuf;
use std::sync::Mutex;

/// The serial ports, each a dict: path, vid, pid, manufacturer, product, serial_number and
/// is_luminaire (as `meb device list`).
#[pyfunction]
pub fn list_luminaires(py: Python<'_>) -> PyResult<Py<PyAny>> {
    let ports = py
        .detach(list_ports)
        .map_err(|e| meb_error(Some("cannot list the serial ports"), &e))?;
    let records: Vec<serde_json::Value> = ports
        .iter()
        .map(|p| {
            serde_json::json!({
                "path": p.path.display().to_string(),
                "vid": p.vid,
                "pid": p.pid,
                "manufacturer": p.manufacturer,
                "product": p.product,
                "serial_number": p.serial_number,
                "is_luminaire": p.is_luminaire,
            })
        })
        .collect();
    to_python(py, &records)
}

/// A luminaire on `port` (e.g. /dev/ttyACM0, or the pseudo-terminal `meb device emulate`
/// prints).
#[pyclass(module = "meb", frozen)]
pub struct Luminaire {
    client: Mutex<DeviceClient>,
    port: PathBuf,
}

impl Luminaire {
    /// Runs `f` on the client with the interpreter lock released.
    fn with<T: Send>(
        &self,
        py: Python<'_>,
        what: &str,
        f: impl FnOnce(&mut DeviceClient) -> Result<T, meb_device::DeviceError> + Send,
    ) -> PyResult<T> {
        py.detach(|| {
            let mut client = self.client.lock().map_err(|_| {
                crate::errors::MebError::new_err("the luminaire's client failed earlier")
            })?;
            f(&mut client)
                .map_err(|e| meb_error(Some(&format!("{what} ({})", self.port.display())), &e))
        })
    }
}

#[pymethods]
impl Luminaire {
    /// Opens the luminaire on `port`; `timeout_ms` is the wait for one reply.
    #[new]
    #[pyo3(signature = (port, *, timeout_ms = 500))]
    fn new(py: Python<'_>, port: PathBuf, timeout_ms: u64) -> PyResult<Self> {
        let timeouts = Timeouts {
            reply: std::time::Duration::from_millis(timeout_ms),
            ..Timeouts::default()
        };
        let client = py
            .detach(|| DeviceClient::open(&port, timeouts))
            .map_err(|e| meb_error(Some(&format!("cannot open {}", port.display())), &e))?;
        Ok(Self {
            client: Mutex::new(client),
            port,
        })
    }

    /// Firmware, protocol version, board, LED and chip-rate limits (`meb device info`).
    fn info(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        let info = self.with(py, "cannot read the luminaire's info", |c| c.info())?;
        to_python(py, &info)
    }

    /// Running, faults, unsaved changes, save state, link counters (`meb device status`).
    fn status(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        let status = self.with(py, "cannot read the luminaire's status", |c| c.status())?;
        to_python(py, &status)
    }

    /// The active configuration: leds, rate (Hz), brightness, phase and modulation depth per
    /// LED, allow_flicker, running.
    fn get(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        let config = self.with(py, "cannot read the luminaire's configuration", |c| {
            c.config()
        })?;
        let n = usize::from(config.led_count).min(MAX_LEDS);
        to_python(
            py,
            &serde_json::json!({
                "leds": config.led_count,
                "rate": config.chip_rate.hz(),
                "brightness": config.brightness_permille[..n],
                "phase": config.phase_chips[..n],
                "depth": (0..n).map(|led| flicker::played_depth(&config, led)).collect::<Vec<_>>(),
                "allow_flicker": config.allow_flicker,
                "running": config.running,
            }),
        )
    }

    /// Applies a configuration (not saved; `save` persists it): `leds` LEDs at chip `rate` Hz
    /// (= the camera frame rate), per-LED `brightness` in per mille and carrier `phase` in
    /// chips (defaults: full brightness, no delay), modulation `depth` (on − off)/(on + off):
    /// "auto" (each LED's largest IEEE 1789 low-risk depth), one depth in (0, 1] or one per
    /// LED (default: the luminaire's current depths). A configuration above IEEE 1789 low risk
    /// is refused with what would be low-risk unless `allow_flicker`. The running state is
    /// kept.
    #[pyo3(signature = (leds, rate, *, brightness = None, phase = None, depth = None, allow_flicker = false))]
    #[allow(clippy::too_many_arguments)]
    fn set(
        &self,
        py: Python<'_>,
        leds: u8,
        rate: f64,
        brightness: Option<Vec<u16>>,
        phase: Option<Vec<u16>>,
        depth: Option<DepthArg>,
        allow_flicker: bool,
    ) -> PyResult<()> {
        let depth = depth.map(|d| d.request()).transpose()?;
        let request = SettingsRequest {
            leds,
            rate_hz: rate,
            brightness: brightness.as_deref(),
            phase: phase.as_deref(),
            depth: depth.as_ref(),
            allow_flicker,
        };
        let current = self.with(py, "cannot read the luminaire's configuration", |c| {
            c.config()
        })?;
        let config = settings::configure(&request, &current, &PYTHON)
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        check_flicker(py, &config, allow_flicker, "set")?;
        self.with(py, "cannot apply the configuration", |c| {
            c.set_config(&config)
        })
    }

    /// Persists the active configuration to flash and waits for it; returns "saved" or
    /// "already saved". A configuration above IEEE 1789 low risk is refused unless
    /// `allow_flicker` (the luminaire then plays it at power-up instead of limiting it).
    #[pyo3(signature = (*, allow_flicker = false))]
    fn save(&self, py: Python<'_>, allow_flicker: bool) -> PyResult<&'static str> {
        let current = self.with(py, "cannot read the luminaire's configuration", |c| {
            c.config()
        })?;
        check_flicker(py, &current, allow_flicker, "save")?;
        let outcome = self.with(py, "cannot save the configuration", |c| c.save_and_wait())?;
        Ok(match outcome {
            SaveOutcome::AlreadySaved => "already saved",
            SaveOutcome::Deferred => "saved",
        })
    }

    /// Starts playing the carriers.
    fn start(&self, py: Python<'_>) -> PyResult<()> {
        self.with(py, "cannot start the carriers", |c| c.start())
    }

    /// Stops playing the carriers (LEDs off).
    fn stop(&self, py: Python<'_>) -> PyResult<()> {
        self.with(py, "cannot stop the carriers", |c| c.stop())
    }

    /// The port it was opened on.
    #[getter]
    fn port(&self) -> PathBuf {
        self.port.clone()
    }

    fn __repr__(&self) -> String {
        format!("Luminaire({:?})", self.port.display().to_string())
    }
}

/// The keyword arguments' names in messages.
const PYTHON: Spelling = Spelling {
    leds: "leds",
    rate: "rate",
    brightness: "brightness",
    phase: "phase",
    depth: "depth",
    depth_auto: "depth=\"auto\"",
    allow_flicker: "pass allow_flicker=True",
};

/// `depth=`: "auto", one depth or one per LED.
#[derive(FromPyObject)]
enum DepthArg {
    Text(String),
    One(f32),
    PerLed(Vec<f32>),
}

impl DepthArg {
    fn request(self) -> PyResult<DepthRequest> {
        let depths = match self {
            DepthArg::Text(text) => {
                return DepthRequest::parse(&text, &PYTHON)
                    .map_err(|e| PyValueError::new_err(e.to_string()));
            }
            DepthArg::One(d) => vec![d],
            DepthArg::PerLed(depths) => depths,
        };
        if let Some(bad) = depths.iter().find(|d| !(**d > 0.0 && **d <= 1.0)) {
            return Err(PyValueError::new_err(format!(
                "depth {bad}: a depth in (0, 1] or \"auto\" expected"
            )));
        }
        Ok(DepthRequest::Depths(depths))
    }
}

/// Refuses `config` above IEEE 1789 low risk (a `ValueError` saying what would be low-risk)
/// unless `allowed`, which warns.
fn check_flicker(
    py: Python<'_>,
    config: &LuminaireConfig,
    allowed: bool,
    command: &str,
) -> PyResult<()> {
    let Some(excess) = settings::flicker_excess(config) else {
        return Ok(());
    };
    if allowed {
        return warn(
            py,
            &format!(
                "LED {} flickers above IEEE 1789 low risk (accepted with allow_flicker=True)",
                excess.led + 1
            ),
        );
    }
    Err(PyValueError::new_err(excess.refusal(command, &PYTHON)))
}
