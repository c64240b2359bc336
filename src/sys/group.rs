//! Looking a group up by name (`getgrnam_r(3)`, which also consults NSS, unlike reading
//! `/etc/group`), for the control socket's group.

use std::ffi::CString;

/// The gid of group `name`, `Ok(None)` when there is no such group.
pub fn group_id(name: &str) -> std::io::Result<Option<u32>> {
    let cname = CString::new(name).map_err(|_| {
        std::io::Error::new(std::io::ErrorKind::InvalidInput, "a group name has no NUL")
    })?;
    let mut buf = vec![0 as libc::c_char; 16 * 1024];
    loop {
        // SAFETY: `libc::group` is a plain C struct of integers and pointers, for which all
        // zero bytes (null pointers) is a valid value.
        let mut group: libc::group = unsafe { std::mem::zeroed() };
        let mut result: *mut libc::group = std::ptr::null_mut();
        // SAFETY: `group` and `result` are out-parameters written by getgrnam_r; `buf` is a
        // live buffer of the length passed; `cname` is NUL-terminated. The strings the
        // group entry points to live in `buf`, which outlives every read of `group` here.
        let rc = unsafe {
            libc::getgrnam_r(
                cname.as_ptr(),
                &mut group,
                buf.as_mut_ptr(),
                buf.len(),
                &mut result,
            )
        };
        if rc == libc::ERANGE && buf.len() < 1 << 20 {
            buf.resize(buf.len() * 4, 0);
            continue;
        }
        if rc != 0 {
            return Err(std::io::Error::from_raw_os_error(rc));
        }
        return Ok((!result.is_null()).then_some(group.gr_gid));
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn root_is_gid_0_and_nonsense_is_none() {
        assert_eq!(super::group_id("root").unwrap(), Some(0));
        assert_eq!(super::group_id("no-such-group-edmd").unwrap(), None);
        assert!(super::group_id("a\0b").is_err());
    }
}
