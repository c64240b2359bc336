//! LinuxCNC's HAL library (`liblinuxcnchal.so.0`, or `hal.library`), loaded when a component
//! is made, never linked: edmd builds and runs without LinuxCNC, and only `output.kind = "hal"` needs it.
//!
//! The calls of HAL's C API used, as `hal.h` declares them: `hal_init` (a userspace
//! component, joining the HAL that `halrun` or `linuxcnc` started), `hal_malloc` (a word in
//! HAL's shared memory for each pin's data pointer), `hal_pin_{bit,float,s32}_new`,
//! `hal_ready` and `hal_exit`; for a component left behind by a killed edmd,
//! `hal_comp_name`, `hal_get_lock` and `rtapi_init` ([`Hal::remove_dead`]). A pin is a
//! pointer, kept in that shared word, to the value: HAL points it at the signal the pin is
//! netted to, so it is read through both every time. Pins are plain machine words that HAL's
//! own components read and write without locks; a bit is a C `bool` (read here as a byte), a
//! float a `double`, an s32 an `int32_t`, all `volatile`.
//!
//! This file is the only one of the module with `unsafe`.

use std::ffi::{CStr, CString, c_char, c_int, c_long, c_uchar, c_void};
use std::ptr;
use std::sync::Arc;

use super::HalError;

/// `hal_pin_dir_t`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(i32)]
pub enum Dir {
    In = 16,
    Out = 32,
}

// SAFETY: `hal_init(const char *name)`, as `hal.h` declares it (and `rtapi_init(const char
// *modname)`, `rtapi.h`, of the same type); each call says why it is sound.
type InitFn = unsafe extern "C" fn(*const c_char) -> c_int;
// SAFETY: `hal_ready(int comp_id)` and `hal_exit(int comp_id)`.
type IdFn = unsafe extern "C" fn(c_int) -> c_int;
// SAFETY: `hal_malloc(long size)`.
type MallocFn = unsafe extern "C" fn(c_long) -> *mut c_void;
// SAFETY: `hal_pin_{bit,float,s32}_new(const char *name, hal_pin_dir_t dir, T **data_ptr_addr,
// int comp_id)`.
type PinNewFn = unsafe extern "C" fn(*const c_char, c_int, *mut c_void, c_int) -> c_int;
// SAFETY: `char *hal_comp_name(int comp_id)`.
type NameFn = unsafe extern "C" fn(c_int) -> *const c_char;
// SAFETY: `unsigned char hal_get_lock(void)`.
type LockFn = unsafe extern "C" fn() -> c_uchar;

/// What `hal_get_lock` answers (`-EINVAL` as an unsigned char) while this process has not
/// mapped HAL's shared memory; a real lock is a mask of `HAL_LOCK_*` bits, never this.
const LOCK_UNMAPPED: c_uchar = (-22i32) as c_uchar;

/// The calls edmd makes, looked up once.
struct Api {
    init: InitFn,
    ready: IdFn,
    exit: IdFn,
    malloc: MallocFn,
    bit_new: PinNewFn,
    float_new: PinNewFn,
    s32_new: PinNewFn,
    comp_name: NameFn,
    get_lock: LockFn,
    rtapi_init: InitFn,
    /// Kept open while any function pointer above may be called.
    _lib: libloading::Library,
}

impl Api {
    fn load(library: &str) -> Result<Api, HalError> {
        let missing = |e: libloading::Error| HalError::Library {
            reason: e.to_string(),
        };
        // SAFETY: loading runs the library's initialisers; LinuxCNC's HAL library has none
        // beyond the C runtime's, and the symbols below are looked up with the types `hal.h`
        // and `rtapi.h` give them.
        unsafe {
            let lib = libloading::Library::new(library).map_err(missing)?;
            let api = Api {
                init: *lib.get::<InitFn>(b"hal_init\0").map_err(missing)?,
                ready: *lib.get::<IdFn>(b"hal_ready\0").map_err(missing)?,
                exit: *lib.get::<IdFn>(b"hal_exit\0").map_err(missing)?,
                malloc: *lib.get::<MallocFn>(b"hal_malloc\0").map_err(missing)?,
                bit_new: *lib.get::<PinNewFn>(b"hal_pin_bit_new\0").map_err(missing)?,
                float_new: *lib
                    .get::<PinNewFn>(b"hal_pin_float_new\0")
                    .map_err(missing)?,
                s32_new: *lib.get::<PinNewFn>(b"hal_pin_s32_new\0").map_err(missing)?,
                comp_name: *lib.get::<NameFn>(b"hal_comp_name\0").map_err(missing)?,
                get_lock: *lib.get::<LockFn>(b"hal_get_lock\0").map_err(missing)?,
                rtapi_init: *lib.get::<InitFn>(b"rtapi_init\0").map_err(missing)?,
                _lib: lib,
            };
            Ok(api)
        }
    }
}

/// HAL's library, loaded: components are joined through it.
pub struct Hal {
    api: Arc<Api>,
}

impl Hal {
    pub fn load(library: &str) -> Result<Hal, HalError> {
        Ok(Hal {
            api: Arc::new(Api::load(library)?),
        })
    }

    /// Joins the running HAL as component `name`.
    pub fn join(&self, name: &str) -> Result<Arc<Component>, HalError> {
        let c_name = CString::new(name).map_err(|_| HalError::Name(name.to_string()))?;
        // SAFETY: `c_name` is a valid C string for the duration of the call.
        let id = unsafe { (self.api.init)(c_name.as_ptr()) };
        if id < 0 {
            return Err(HalError::Init {
                component: name.to_string(),
                code: id,
            });
        }
        Ok(Arc::new(Component {
            api: self.api.clone(),
            id,
            name: name.to_string(),
        }))
    }

    /// The name of component `id` in the running HAL (`None`: no such component, or HAL's
    /// memory not mapped in this process).
    pub fn name_of(&self, id: c_int) -> Option<String> {
        if !self.mapped() {
            return None;
        }
        // SAFETY: HAL's memory is mapped (checked above); `hal_comp_name` looks `id` up under
        // HAL's mutex and returns the component's name in shared memory, or null.
        unsafe {
            let name = (self.api.comp_name)(id);
            (!name.is_null()).then(|| CStr::from_ptr(name).to_string_lossy().into_owned())
        }
    }

    /// HAL's shared memory is mapped in this process (a `hal_init` reached it).
    fn mapped(&self) -> bool {
        // SAFETY: `hal_get_lock` reads HAL's lock word if the memory is mapped and answers
        // `-EINVAL` otherwise; it takes no argument and changes nothing.
        unsafe { (self.api.get_lock)() != LOCK_UNMAPPED }
    }

    /// Removes component `id`, named `name`, which a process that died without leaving HAL
    /// (a killed edmd) left behind with its pins: its name can be joined again. Call only
    /// after [`join`](Self::join) was refused for that name, with no component of this
    /// process's own in HAL yet.
    ///
    /// HAL's library counts, per process, the components it made and releases its mapping
    /// when a `hal_exit` brings the count to zero, and each `hal_exit` also ends one RTAPI
    /// module. Exiting another process's component here is one exit more than this process
    /// made: after a refused `hal_init` the count is zero, so it goes below zero (no release:
    /// the mapping stays, and the next `hal_init` brings it back to zero), and one more
    /// `rtapi_init` first keeps RTAPI's module count from reaching zero (which would unmap
    /// its memory under a later `rtapi_init`).
    pub fn remove_dead(&self, id: c_int, name: &str) -> Result<(), HalError> {
        match self.name_of(id) {
            Some(found) if found == name => {}
            // Gone already, or the id is another component's now: nothing of ours to remove.
            _ => return Ok(()),
        }
        // SAFETY: a valid C string; `rtapi_init` only registers a module (see above).
        let module = unsafe { (self.api.rtapi_init)(c"edmd-reap".as_ptr()) };
        if module < 0 {
            return Err(HalError::Call {
                call: "rtapi_init (to remove a dead component)".to_string(),
                code: module,
            });
        }
        // SAFETY: `id` names a component of `name` whose process is dead (the caller
        // checked); `hal_exit` unlinks its pins from their signals and frees them under HAL's
        // mutex. The counts are kept as the doc comment explains.
        let code = unsafe { (self.api.exit)(id) };
        if code < 0 {
            return Err(HalError::Call {
                call: format!("hal_exit of the dead component {name} ({id})"),
                code,
            });
        }
        Ok(())
    }
}

/// A HAL userspace component: its id in the running HAL, removed (with its pins) on drop.
pub struct Component {
    api: Arc<Api>,
    id: c_int,
    name: String,
}

impl Component {
    /// The component's id in the running HAL.
    pub fn id(&self) -> c_int {
        self.id
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// Tells HAL the component has made its pins (`loadusr -W` waits for this).
    pub fn ready(&self) -> Result<(), HalError> {
        // SAFETY: `id` came from `hal_init` and the component has not exited.
        let code = unsafe { (self.api.ready)(self.id) };
        self.checked("hal_ready", code)
    }

    fn checked(&self, what: &str, code: c_int) -> Result<(), HalError> {
        if code < 0 {
            return Err(HalError::Call {
                call: format!("{what} ({})", self.name),
                code,
            });
        }
        Ok(())
    }

    /// A new pin `name` of the kind `new` makes, its data pointer kept in shared memory.
    fn pin<T>(&self, name: &str, dir: Dir, new: PinNewFn) -> Result<*mut *mut T, HalError> {
        let c_name = CString::new(name).map_err(|_| HalError::Name(name.to_string()))?;
        // SAFETY: `hal_malloc` returns memory in HAL's shared segment (or null), aligned for
        // any of HAL's types, which lives as long as HAL does.
        let slot = unsafe { (self.api.malloc)(std::mem::size_of::<*mut T>() as c_long) };
        if slot.is_null() {
            return Err(HalError::Call {
                call: format!("hal_malloc for {name}"),
                code: -12,
            });
        }
        // SAFETY: `c_name` is a valid C string, `slot` a writable pointer-sized word in HAL's
        // memory, `id` a live component: the pin constructor stores the data pointer there.
        let code = unsafe { new(c_name.as_ptr(), dir as c_int, slot, self.id) };
        self.checked(&format!("the pin {name}"), code)?;
        Ok(slot.cast())
    }

    pub fn bit(self: &Arc<Self>, name: &str, dir: Dir) -> Result<BitPin, HalError> {
        let slot = self.pin(name, dir, self.api.bit_new)?;
        Ok(BitPin(Pin {
            slot,
            _component: self.clone(),
        }))
    }

    pub fn float(self: &Arc<Self>, name: &str, dir: Dir) -> Result<Pin<f64>, HalError> {
        let slot = self.pin(name, dir, self.api.float_new)?;
        Ok(Pin {
            slot,
            _component: self.clone(),
        })
    }

    pub fn s32(self: &Arc<Self>, name: &str, dir: Dir) -> Result<Pin<i32>, HalError> {
        let slot = self.pin(name, dir, self.api.s32_new)?;
        Ok(Pin {
            slot,
            _component: self.clone(),
        })
    }
}

impl Drop for Component {
    fn drop(&mut self) {
        // SAFETY: `id` came from `hal_init`; no pin outlives the component (each holds it).
        unsafe {
            (self.api.exit)(self.id);
        }
    }
}

/// One pin: read and written through HAL's data pointer, which HAL moves when the pin is
/// netted or unlinked.
pub struct Pin<T> {
    slot: *mut *mut T,
    /// The pin lives in the component's memory: the component outlives it.
    _component: Arc<Component>,
}

// SAFETY: a pin is a word in HAL's shared memory, written by one side (HAL's threads for an
// input, edmd's consumer thread for an output) and read by the other, as HAL's own
// components do without locks; `T` is a plain machine word (a byte, f64, i32).
unsafe impl<T: Copy> Send for Pin<T> {}
// SAFETY: as above; reads and writes are single volatile word accesses.
unsafe impl<T: Copy> Sync for Pin<T> {}

impl<T: Copy> Pin<T> {
    pub fn get(&self) -> T {
        // SAFETY: `slot` holds the pin's data pointer, set by HAL when the pin was made and
        // kept valid (pointing at the pin's own value or its signal's) while the component
        // lives, which `_component` ensures.
        unsafe {
            let data: *mut T = ptr::read_volatile(self.slot);
            ptr::read_volatile(data)
        }
    }

    pub fn set(&self, value: T) {
        // SAFETY: as for `get`; an output pin's value is written by this component only.
        unsafe {
            let data: *mut T = ptr::read_volatile(self.slot);
            ptr::write_volatile(data, value)
        }
    }
}

/// A bit pin: a C `bool`, read as a byte (HAL writes 0 or 1; anything else counts as set).
#[derive(Debug)]
pub struct BitPin(Pin<u8>);

impl BitPin {
    pub fn get(&self) -> bool {
        self.0.get() != 0
    }

    pub fn set(&self, value: bool) {
        self.0.set(u8::from(value));
    }
}

impl<T> std::fmt::Debug for Pin<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Pin")
    }
}
