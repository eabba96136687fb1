//! ONNX Runtime, loaded at run time from a shared library (`ort` with `load-dynamic`): where the
//! library is looked for, its version check, one process-wide environment, and session options
//! (threads, CUDA).

use std::ffi::CStr;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use ort::ep::ExecutionProvider;
use ort::session::Session;

use super::error::ModelError;

/// The ONNX Runtime minor version the `ort` API level compiled here needs (1.x).
pub fn required_minor_version() -> u32 {
    ort::MINOR_VERSION
}

/// How sessions are created.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RuntimeOptions {
    /// The shared library; `None` = `ORT_DYLIB_PATH`, then the `onnxruntime` Python wheel.
    pub library: Option<PathBuf>,
    /// Threads inside one operator; 0 = ONNX Runtime's default (one per physical core).
    pub intra_threads: usize,
    /// Threads across independent operators; 0 = ONNX Runtime's default.
    pub inter_threads: usize,
    /// Let ONNX Runtime's threads spin-wait for work between operators and runs (its own
    /// default): a little less latency per answer for a busy core while they wait.
    pub spin_wait: bool,
    /// Register the CUDA execution provider when the library offers it (CPU otherwise).
    pub cuda: bool,
}

/// A loaded ONNX Runtime: the library, its version and the options sessions are made with.
#[derive(Debug)]
pub struct OrtRuntime {
    library: PathBuf,
    version: String,
    environment: ort::environment::Environment,
    options: RuntimeOptions,
}

/// The environment is process-wide in ONNX Runtime (and `ort` allows one), so the first
/// successful load is kept and shared by every [`OrtRuntime`].
static LOADED: Mutex<Option<LoadedLibrary>> = Mutex::new(None);

#[derive(Clone)]
struct LoadedLibrary {
    library: PathBuf,
    version: String,
    environment: ort::environment::Environment,
}

impl OrtRuntime {
    /// Finds and loads the library (once per process) and keeps `options` for new sessions.
    pub fn load(options: RuntimeOptions) -> Result<Arc<OrtRuntime>, ModelError> {
        // A configured path that does not exist is an error even when another load already
        // succeeded in this process: the configuration is wrong either way.
        if let Some(configured) = &options.library {
            existing(configured, "models.ort_library")?;
        }
        let mut loaded = LOADED
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        let library = match loaded.as_ref() {
            Some(library) => {
                let wanted = options.library.as_deref();
                if let Some(wanted) = wanted
                    && !same_file(wanted, &library.library)
                {
                    tracing::warn!(
                        requested = %wanted.display(),
                        loaded = %library.library.display(),
                        "ONNX Runtime is already loaded from another file in this process; using it"
                    );
                }
                library.clone()
            }
            None => {
                let path = locate_library(options.library.as_deref())?;
                let library = load_library(&path)?;
                *loaded = Some(library.clone());
                library
            }
        };
        Ok(Arc::new(OrtRuntime {
            library: library.library,
            version: library.version,
            environment: library.environment,
            options,
        }))
    }

    pub fn library(&self) -> &Path {
        &self.library
    }

    pub fn version(&self) -> &str {
        &self.version
    }

    pub fn options(&self) -> &RuntimeOptions {
        &self.options
    }

    /// Opens `path` with this runtime's threads and execution providers. Returns the session and
    /// the execution provider it runs on.
    pub fn open_session(&self, path: &Path) -> Result<(Session, &'static str), String> {
        let options = self.options.clone();
        let environment = self.environment.clone();
        let path = path.to_path_buf();
        // ONNX Runtime reports errors as statuses, but `ort` asserts on some internal
        // invariants; a panic there must not take the service down.
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(move || {
            build_session(&environment, &options, &path)
        }))
        .unwrap_or_else(|panic| Err(format!("ONNX Runtime panicked: {}", panic_text(&panic))))
    }
}

fn build_session(
    environment: &ort::environment::Environment,
    options: &RuntimeOptions,
    path: &Path,
) -> Result<(Session, &'static str), String> {
    let text = |error: ort::Error<ort::session::builder::SessionBuilder>| error.to_string();
    let mut builder = Session::builder(environment).map_err(|error| error.to_string())?;
    if options.intra_threads > 0 {
        builder = builder
            .with_intra_threads(options.intra_threads)
            .map_err(text)?;
    }
    if options.inter_threads > 0 {
        builder = builder
            .with_inter_threads(options.inter_threads)
            .map_err(text)?;
    }
    builder = builder
        .with_intra_op_spinning(options.spin_wait)
        .map_err(text)?
        .with_inter_op_spinning(options.spin_wait)
        .map_err(text)?;
    let mut provider = "CPUExecutionProvider";
    if options.cuda {
        let cuda = ort::ep::CUDA::default();
        match ort::ep::CUDA::is_available() {
            Ok(true) => match cuda.register(&mut builder) {
                Ok(()) => provider = "CUDAExecutionProvider",
                Err(error) => tracing::warn!(
                    %error,
                    "the CUDA execution provider did not register; running on the CPU"
                ),
            },
            Ok(false) => tracing::info!(
                "this ONNX Runtime has no CUDA execution provider; models run on the CPU"
            ),
            Err(error) => {
                tracing::warn!(%error, "cannot list execution providers; running on the CPU")
            }
        }
    }
    let session = builder
        .commit_from_file(path)
        .map_err(|error| error.to_string())?;
    Ok((session, provider))
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => a == b,
    }
}

fn panic_text(panic: &Box<dyn std::any::Any + Send>) -> String {
    if let Some(text) = panic.downcast_ref::<&str>() {
        (*text).to_string()
    } else if let Some(text) = panic.downcast_ref::<String>() {
        text.clone()
    } else {
        "unknown panic".to_string()
    }
}

/// The library to load: the configured path, else `ORT_DYLIB_PATH`, else the newest
/// `libonnxruntime` inside an `onnxruntime` Python wheel.
pub fn locate_library(configured: Option<&Path>) -> Result<PathBuf, ModelError> {
    if let Some(path) = configured {
        return existing(path, "models.ort_library");
    }
    if let Some(path) = std::env::var_os("ORT_DYLIB_PATH").filter(|value| !value.is_empty()) {
        return existing(Path::new(&path), "ORT_DYLIB_PATH");
    }
    let site_dirs = python_site_packages();
    if let Some(path) = newest_wheel_library(&site_dirs) {
        return Ok(path);
    }
    Err(ModelError::LibraryNotFound {
        tried: format!(
            "models.ort_library and ORT_DYLIB_PATH are not set, and no onnxruntime/capi/libonnxruntime.* in {}",
            if site_dirs.is_empty() {
                "any Python site-packages (python3 not found)".to_string()
            } else {
                site_dirs
                    .iter()
                    .map(|dir| dir.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            }
        ),
    })
}

fn existing(path: &Path, source: &str) -> Result<PathBuf, ModelError> {
    if path.is_file() {
        Ok(path.to_path_buf())
    } else {
        Err(ModelError::LibraryNotFound {
            tried: format!("{source} = {} does not exist", path.display()),
        })
    }
}

/// The Python site-packages directories, asked of `python3` without importing anything heavy.
fn python_site_packages() -> Vec<PathBuf> {
    let script = "import site, sys\nfor p in site.getsitepackages() + [site.getusersitepackages()] + sys.path: print(p)";
    let Ok(output) = std::process::Command::new("python3")
        .args(["-I", "-c", script])
        .output()
    else {
        return Vec::new();
    };
    let mut dirs: Vec<PathBuf> = Vec::new();
    for line in String::from_utf8_lossy(&output.stdout).lines() {
        let dir = PathBuf::from(line.trim());
        if !line.trim().is_empty() && dir.is_dir() && !dirs.contains(&dir) {
            dirs.push(dir);
        }
    }
    dirs
}

/// `libonnxruntime.so.1.32.0` style files under `<site>/onnxruntime/capi/`, highest version first.
fn newest_wheel_library(site_dirs: &[PathBuf]) -> Option<PathBuf> {
    let mut found: Vec<(Vec<u32>, PathBuf)> = Vec::new();
    for site in site_dirs {
        let capi = site.join("onnxruntime").join("capi");
        let Ok(entries) = std::fs::read_dir(&capi) else {
            continue;
        };
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            if let Some(version) = library_file_version(&name) {
                found.push((version, entry.path()));
            }
        }
    }
    found.sort();
    found.pop().map(|(_, path)| path)
}

/// The version in a runtime library's file name (`libonnxruntime.so.1.32.0` -> [1, 32, 0],
/// `libonnxruntime.1.32.0.dylib`, `onnxruntime.dll` -> []), or `None` for other files.
fn library_file_version(name: &str) -> Option<Vec<u32>> {
    let rest = name
        .strip_prefix("libonnxruntime")
        .or_else(|| name.strip_prefix("onnxruntime"))?;
    let numbers: Vec<u32> = rest
        .split('.')
        .filter_map(|part| part.parse::<u32>().ok())
        .collect();
    let is_library = rest.starts_with(".so") || rest.ends_with(".dylib") || rest == ".dll";
    is_library.then_some(numbers)
}

fn load_library(path: &Path) -> Result<LoadedLibrary, ModelError> {
    let absolute = path.canonicalize().map_err(|source| ModelError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let version = library_version(&absolute)?;
    let needed = format!("1.{}", required_minor_version());
    if minor_version(&version).is_none_or(|minor| minor < required_minor_version()) {
        return Err(ModelError::LibraryTooOld {
            path: absolute,
            found: version,
            needed,
        });
    }
    let for_closure = absolute.clone();
    let environment = std::panic::catch_unwind(std::panic::AssertUnwindSafe(move || {
        ort::init_from(&for_closure)
            .map_err(|error| error.to_string())?
            .with_name("segsplat")
            .build()
            .map_err(|error| error.to_string())
    }))
    .unwrap_or_else(|panic| Err(format!("panicked: {}", panic_text(&panic))))
    .map_err(|reason| ModelError::LibraryLoad {
        path: absolute.clone(),
        reason,
    })?;
    tracing::info!(library = %absolute.display(), %version, "ONNX Runtime loaded");
    Ok(LoadedLibrary {
        library: absolute,
        version,
        environment,
    })
}

/// Why the dynamic loader refused `path`, said in terms of what the file is: a file that is no
/// shared library at all reads as that, not only as the loader's "invalid ELF header".
fn unloadable_library(path: &Path, loader_error: &str) -> String {
    let mut head = [0u8; 4];
    let read = std::fs::File::open(path)
        .and_then(|mut file| std::io::Read::read(&mut file, &mut head))
        .unwrap_or(0);
    let head = &head[..read];
    let is_library = head.starts_with(b"\x7fELF")
        || head.starts_with(b"MZ")
        || [
            [0xfe, 0xed, 0xfa, 0xcf],
            [0xcf, 0xfa, 0xed, 0xfe],
            [0xca, 0xfe, 0xba, 0xbe],
        ]
        .iter()
        .any(|magic| head == magic);
    let named_like_ort = path
        .file_name()
        .and_then(|name| name.to_str())
        .is_some_and(|name| name.contains("onnxruntime"));
    if !is_library {
        format!(
            "this is not a shared library at all (no ELF, Mach-O or PE header), so not ONNX \
             Runtime; point at ONNX Runtime's libonnxruntime (e.g. from `pip install \
             onnxruntime`). The loader said: {loader_error}"
        )
    } else if !named_like_ort {
        format!(
            "the loader refused this shared library, whose name does not look like ONNX \
             Runtime's (libonnxruntime*): {loader_error}"
        )
    } else {
        format!("the loader refused it: {loader_error}")
    }
}

fn minor_version(version: &str) -> Option<u32> {
    let mut parts = version.split('.');
    let major: u32 = parts.next()?.parse().ok()?;
    let minor: u32 = parts.next()?.parse().ok()?;
    (major == 1).then_some(minor)
}

/// Reads the library's version string (`OrtGetApiBase()->GetVersionString()`) before `ort`
/// initialises it, so a too-old library is named with its version instead of failing later.
#[allow(unsafe_code, clippy::mem_forget)]
pub fn library_version(path: &Path) -> Result<String, ModelError> {
    let load_error = |reason: String| ModelError::LibraryLoad {
        path: path.to_path_buf(),
        reason,
    };
    // SAFETY: loading runs the library's initialisers; this is the ONNX Runtime library the
    // operator pointed us at, which `ort` loads the same way.
    let library = unsafe { libloading::Library::new(path) }
        .map_err(|error| load_error(unloadable_library(path, &error.to_string())))?;
    // SAFETY: `OrtGetApiBase` has this signature in every ONNX Runtime release (C API, stable).
    let get_api_base: libloading::Symbol<unsafe extern "C" fn() -> *const ort::sys::OrtApiBase> =
        unsafe { library.get(b"OrtGetApiBase") }.map_err(|_| {
            load_error(
                "this is a shared library, but not ONNX Runtime (it has no OrtGetApiBase); \
                     point at ONNX Runtime's libonnxruntime (e.g. from `pip install onnxruntime`)"
                    .to_string(),
            )
        })?;
    // SAFETY: the function takes no arguments and returns a pointer to a static struct.
    let base = unsafe { get_api_base() };
    if base.is_null() {
        return Err(load_error("OrtGetApiBase returned null".to_string()));
    }
    // SAFETY: `base` is non-null and points to the library's static `OrtApiBase`;
    // `GetVersionString` returns a static NUL-terminated string.
    let version = unsafe {
        let text = ((*base).GetVersionString)();
        if text.is_null() {
            return Err(load_error("GetVersionString returned null".to_string()));
        }
        CStr::from_ptr(text).to_string_lossy().into_owned()
    };
    // Keep the library mapped: `ort` opens it again and the loader shares one handle; unloading
    // a runtime with live threads is never safe.
    std::mem::forget(library);
    Ok(version)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wheel_library_names_are_recognised_with_versions() {
        assert_eq!(
            library_file_version("libonnxruntime.so.1.32.0"),
            Some(vec![1, 32, 0])
        );
        assert_eq!(library_file_version("libonnxruntime.so"), Some(vec![]));
        assert_eq!(
            library_file_version("libonnxruntime.1.31.1.dylib"),
            Some(vec![1, 31, 1])
        );
        assert_eq!(
            library_file_version("libonnxruntime_providers_shared.so"),
            None
        );
        assert_eq!(library_file_version("onnxruntime_pybind11_state.so"), None);
    }

    #[test]
    fn minor_versions_parse() {
        assert_eq!(minor_version("1.32.0"), Some(32));
        assert_eq!(minor_version("2.0.0"), None);
        assert_eq!(minor_version("garbage"), None);
    }

    #[test]
    fn a_file_that_is_no_library_is_named_as_such() {
        let dir = tempfile::tempdir().expect("temp dir");
        let text = dir.path().join("libonnxruntime.so");
        std::fs::write(&text, "not a library").expect("write");
        let error = library_version(&text).expect_err("a text file is no library");
        assert!(
            error.to_string().contains("not a shared library at all"),
            "{error}"
        );
        let elf = dir.path().join("libz.so");
        std::fs::write(&elf, b"\x7fELF truncated").expect("write");
        assert!(
            unloadable_library(&elf, "dlopen failed").contains("does not look like ONNX Runtime"),
        );
    }
}
