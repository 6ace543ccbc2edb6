//! The exceptions of the Python package: every one a `dhct.DhctError`, carrying the
//! command line's message.

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

create_exception!(
    _dhct,
    DhctError,
    PyException,
    "Base class of every error dhct raises."
);
create_exception!(
    _dhct,
    ReadError,
    DhctError,
    "A file could not be read, or holds no usable image (wrong format, truncated, missing channel)."
);
create_exception!(
    _dhct,
    OptionError,
    DhctError,
    "An option, config file, mask or geometry is invalid (the message names it and the valid values)."
);
create_exception!(
    _dhct,
    InputMismatchError,
    DhctError,
    "The image does not match the lattice or constant given (the message says what it shows and which option to change)."
);
create_exception!(
    _dhct,
    AnalysisError,
    DhctError,
    "The analysis failed on this image (too few features, the lattice not found, ...)."
);
create_exception!(
    _dhct,
    WriteError,
    DhctError,
    "The outputs could not be written (the folder holds other files, another run holds its lock, ...)."
);
create_exception!(
    _dhct,
    SimulationError,
    DhctError,
    "A simulation config is invalid or the simulation failed."
);

/// `error` (with its whole context chain, as the command line prints it) as `E`.
pub fn to_py<E: pyo3::type_object::PyTypeInfo>(error: &anyhow::Error) -> PyErr {
    PyErr::new::<E, _>(format!("{error:#}"))
}

/// Registers every exception class in `module`.
pub fn register(module: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = module.py();
    module.add("DhctError", py.get_type::<DhctError>())?;
    module.add("ReadError", py.get_type::<ReadError>())?;
    module.add("OptionError", py.get_type::<OptionError>())?;
    module.add("InputMismatchError", py.get_type::<InputMismatchError>())?;
    module.add("AnalysisError", py.get_type::<AnalysisError>())?;
    module.add("WriteError", py.get_type::<WriteError>())?;
    module.add("SimulationError", py.get_type::<SimulationError>())?;
    Ok(())
}
