//! `meb.Luminaire`: a luminaire on a serial port (or the virtual one of `meb device
//! emulate`) through [`meb_device::DeviceClient`], the client of `meb device`.

use crate::errors::meb_error;
use crate::json::to_python;
use meb_device::discovery::list_ports;
use meb_device::{DeviceClient, Timeouts};
use protocol::carriers::MAX_LEDS;
use protocol::config::{ChipRate, FULL_BRIGHTNESS_PERMILLE, LuminaireConfig};
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

    /// The active configuration: leds, rate (Hz), brightness and phase per LED, running.
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
                "running": config.running,
            }),
        )
    }

    /// Applies a configuration (not saved; `save` persists it): `leds` LEDs at chip `rate` Hz
    /// (= the camera frame rate), per-LED `brightness` in per mille and carrier `phase` in
    /// chips (defaults: full brightness, no delay). The running state is kept.
    #[pyo3(signature = (leds, rate, *, brightness = None, phase = None))]
    fn set(
        &self,
        py: Python<'_>,
        leds: u8,
        rate: f64,
        brightness: Option<Vec<u16>>,
        phase: Option<Vec<u16>>,
    ) -> PyResult<()> {
        let n = usize::from(leds);
        if n == 0 || n > MAX_LEDS {
            return Err(PyValueError::new_err(format!(
                "leds {leds} is outside 1..={MAX_LEDS}"
            )));
        }
        let (min, max) = (ChipRate::MIN.hz(), ChipRate::MAX.hz());
        if !(rate >= min && rate <= max) {
            return Err(PyValueError::new_err(format!(
                "rate {rate} Hz is outside the supported {min:.3}..={max:.3} Hz"
            )));
        }
        let per_led =
            |name: &str, values: Option<Vec<u16>>, default: u16| -> PyResult<[u16; MAX_LEDS]> {
                let mut out = [default; MAX_LEDS];
                if let Some(values) = values {
                    if values.len() != n {
                        return Err(PyValueError::new_err(format!(
                            "{name} needs {n} values (one per LED), got {}",
                            values.len()
                        )));
                    }
                    out[..n].copy_from_slice(&values);
                }
                Ok(out)
            };
        let brightness = per_led("brightness", brightness, FULL_BRIGHTNESS_PERMILLE)?;
        let phase = per_led("phase", phase, 0)?;
        let current = self.with(py, "cannot read the luminaire's configuration", |c| {
            c.config()
        })?;
        let config = LuminaireConfig {
            led_count: leds,
            chip_rate: ChipRate::from_hz(rate),
            brightness_permille: brightness,
            phase_chips: phase,
            running: current.running,
        };
        config
            .validate()
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        self.with(py, "cannot apply the configuration", |c| {
            c.set_config(&config)
        })
    }

    /// Persists the active configuration to flash and waits for it; returns "saved" or
    /// "already saved".
    fn save(&self, py: Python<'_>) -> PyResult<&'static str> {
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
