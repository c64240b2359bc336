//! Linux ppdev (`/dev/parportN`) ioctls behind tiny safe wrappers: the only `unsafe` of the
//! parallel port.
//!
//! ```text
//!  open(O_RDWR) ─► PPEXCL (no other driver may share the port) ─► PPCLAIM ─► PPDATADIR forward
//!  ─► PPWDATA / PPWCONTROL the safe state ─► ... job ... ─► Drop: safe state, PPRELEASE, close
//! ```
//!
//! Request numbers follow `<linux/ppdev.h>` with the generic `_IOC` layout (x86, x86-64,
//! arm, aarch64, riscv); the unit tests pin them to the values the C header gives.
//! Each failure of the opening sequence becomes an operator-facing [`ParportError`]:
//! the errno alone ("ENXIO") tells a machine builder nothing about `lp` or `ppdev`.

use std::fs::{File, OpenOptions};
use std::io;
use std::os::fd::AsRawFd;
use std::path::Path;

use super::{ParportError, Port};

const IOC_WRITE: u32 = 1;
const IOC_READ: u32 = 2;
const PP_IOCTL: u32 = b'p' as u32;

const fn ioc(dir: u32, nr: u32, size: u32) -> u32 {
    (dir << 30) | (size << 16) | (PP_IOCTL << 8) | nr
}

pub const PPRSTATUS: u32 = ioc(IOC_READ, 0x81, 1);
pub const PPWCONTROL: u32 = ioc(IOC_WRITE, 0x84, 1);
pub const PPWDATA: u32 = ioc(IOC_WRITE, 0x86, 1);
pub const PPCLAIM: u32 = ioc(0, 0x8b, 0);
pub const PPRELEASE: u32 = ioc(0, 0x8c, 0);
pub const PPEXCL: u32 = ioc(0, 0x8f, 0);
pub const PPDATADIR: u32 = ioc(IOC_WRITE, 0x90, 4);

fn check(rc: libc::c_int) -> io::Result<()> {
    if rc < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(())
    }
}

fn ioctl_none(file: &File, request: u32) -> io::Result<()> {
    // SAFETY: a request without an argument; the fd is open for the lifetime of `file`.
    check(unsafe { libc::ioctl(file.as_raw_fd(), request as _) })
}

fn ioctl_write_u8(file: &File, request: u32, value: u8) -> io::Result<()> {
    // SAFETY: ppdev reads one byte through the pointer (the request's size is 1); `value`
    // lives across the call.
    check(unsafe { libc::ioctl(file.as_raw_fd(), request as _, &value as *const u8) })
}

fn ioctl_write_int(file: &File, request: u32, value: libc::c_int) -> io::Result<()> {
    // SAFETY: ppdev reads one int through the pointer (the request's size is 4).
    check(unsafe { libc::ioctl(file.as_raw_fd(), request as _, &value as *const libc::c_int) })
}

fn ioctl_read_u8(file: &File, request: u32) -> io::Result<u8> {
    let mut value = 0u8;
    // SAFETY: ppdev writes one byte through the pointer (the request's size is 1).
    check(unsafe { libc::ioctl(file.as_raw_fd(), request as _, &mut value as *mut u8) })?;
    Ok(value)
}

/// What an errno means at each step of opening the port, for the operator.
pub(super) fn open_error(path: &Path, step: &'static str, e: io::Error) -> ParportError {
    let path = path.display().to_string();
    match (step, e.raw_os_error()) {
        (_, Some(libc::ENOENT)) | ("open", Some(libc::ENXIO | libc::ENODEV)) => {
            ParportError::Missing { path }
        }
        (_, Some(libc::EACCES | libc::EPERM)) => ParportError::PermissionDenied { path },
        (_, Some(libc::EBUSY)) | ("claim", Some(libc::ENXIO)) => ParportError::Busy { path },
        (_, Some(libc::ENOTTY | libc::EINVAL | libc::EISDIR)) => {
            ParportError::NotAParport { path, source: e }
        }
        _ => ParportError::Io {
            path,
            step,
            source: e,
        },
    }
}

/// A claimed parallel port. Dropping it puts the registers back to the safe state given at
/// open and releases the port, whatever happened in between.
#[derive(Debug)]
pub struct Ppdev {
    file: File,
    safe_data: u8,
    safe_control: u8,
}

impl Ppdev {
    /// Opens and claims `path` exclusively, drives its data pins, and writes the safe register
    /// values (every output inactive) before returning.
    pub fn open(path: &Path, safe_data: u8, safe_control: u8) -> Result<Ppdev, ParportError> {
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .map_err(|e| open_error(path, "open", e))?;
        // Exclusive: a printer driver sharing the port would write to it between our ticks.
        ioctl_none(&file, PPEXCL).map_err(|e| open_error(path, "exclusive", e))?;
        ioctl_none(&file, PPCLAIM).map_err(|e| open_error(path, "claim", e))?;
        // From here on a failure must release the claim: build the guard first.
        let port = Ppdev {
            file,
            safe_data,
            safe_control,
        };
        // A bidirectional port left in reverse mode by the BIOS would not drive pins 2-9.
        ioctl_write_int(&port.file, PPDATADIR, 0).map_err(|e| open_error(path, "data-dir", e))?;
        ioctl_write_u8(&port.file, PPWDATA, safe_data)
            .map_err(|e| open_error(path, "write-data", e))?;
        ioctl_write_u8(&port.file, PPWCONTROL, safe_control)
            .map_err(|e| open_error(path, "write-control", e))?;
        Ok(port)
    }
}

impl Port for Ppdev {
    fn write_data(&mut self, value: u8) -> io::Result<()> {
        ioctl_write_u8(&self.file, PPWDATA, value)
    }

    fn write_control(&mut self, value: u8) -> io::Result<()> {
        ioctl_write_u8(&self.file, PPWCONTROL, value)
    }

    fn read_status(&mut self) -> io::Result<u8> {
        ioctl_read_u8(&self.file, PPRSTATUS)
    }
}

impl Drop for Ppdev {
    fn drop(&mut self) {
        // Best effort: a port that cannot be written any more cannot be made safer.
        let _ = ioctl_write_u8(&self.file, PPWDATA, self.safe_data);
        let _ = ioctl_write_u8(&self.file, PPWCONTROL, self.safe_control);
        let _ = ioctl_none(&self.file, PPRELEASE);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn request_numbers_match_linux_ppdev_h() {
        // Values printed by a C program including <linux/ppdev.h> on x86-64.
        assert_eq!(PPRSTATUS, 0x8001_7081);
        assert_eq!(PPWCONTROL, 0x4001_7084);
        assert_eq!(PPWDATA, 0x4001_7086);
        assert_eq!(PPCLAIM, 0x708b);
        assert_eq!(PPRELEASE, 0x708c);
        assert_eq!(PPEXCL, 0x708f);
        assert_eq!(PPDATADIR, 0x4004_7090);
    }

    #[test]
    fn errnos_become_operator_messages() {
        let p = Path::new("/dev/parport0");
        let e = |step, errno| open_error(p, step, io::Error::from_raw_os_error(errno));
        assert!(matches!(
            e("open", libc::ENOENT),
            ParportError::Missing { .. }
        ));
        assert!(matches!(
            e("open", libc::ENXIO),
            ParportError::Missing { .. }
        ));
        assert!(matches!(
            e("open", libc::EACCES),
            ParportError::PermissionDenied { .. }
        ));
        assert!(matches!(e("claim", libc::ENXIO), ParportError::Busy { .. }));
        assert!(matches!(e("claim", libc::EBUSY), ParportError::Busy { .. }));
        assert!(matches!(
            e("exclusive", libc::ENOTTY),
            ParportError::NotAParport { .. }
        ));
        assert!(matches!(e("open", libc::EIO), ParportError::Io { .. }));
        let text = e("open", libc::EACCES).to_string();
        assert!(text.contains("group `lp`"), "{text}");
        assert!(
            text.contains("parport_pc") && text.contains("ppdev"),
            "{text}"
        );
        let text = e("claim", libc::ENXIO).to_string();
        assert!(text.contains("`lp`"), "{text}");
    }

    #[test]
    fn dev_null_is_not_a_parallel_port_and_a_missing_path_is_missing() {
        let err = Ppdev::open(Path::new("/dev/null"), 0, 0).unwrap_err();
        assert!(matches!(err, ParportError::NotAParport { .. }), "{err}");
        assert!(
            err.to_string()
                .starts_with("/dev/null: not a parallel port")
        );
        let err = Ppdev::open(Path::new("/dev/parport-edmd-missing"), 0, 0).unwrap_err();
        assert!(matches!(err, ParportError::Missing { .. }), "{err}");
    }
}
