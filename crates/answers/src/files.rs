//! Files read on a user's or an operator's behalf (scenario files, map YAMLs and their images),
//! with their type and size checked before any byte is read (docs/api.md "Limits and
//! security"): only regular files are read (a FIFO would block the reader for ever, `/dev/zero`
//! would never end), and never more than the file's cap, even if it grows while it is read.

use std::fs::File;
use std::io::{self, Read};
use std::path::Path;

/// Largest map image file (bytes): four bytes a pixel of the largest image the model decodes
/// (`irs_model::floorplan::MAX_IMAGE_SIDE`², a text P2 PGM of three-digit values and their
/// separators), plus 64 KiB of header and comments. Every image the model accepts fits; a
/// larger file could only be refused after it was read.
pub const MAX_IMAGE_FILE_BYTES: u64 =
    4 * (irs_model::floorplan::MAX_IMAGE_SIDE as u64).pow(2) + (64 << 10);

/// Largest map YAML file (bytes): Nav2's map YAML is seven short lines.
pub const MAX_MAP_YAML_BYTES: u64 = 64 << 10;

/// Largest scenario file (bytes): the largest image in base64 (4 bytes for 3) and 1 MiB for
/// the rest of the document.
pub const MAX_SCENARIO_FILE_BYTES: u64 = MAX_IMAGE_FILE_BYTES.div_ceil(3) * 4 + (1 << 20);

/// Reads `path` whole if it is a regular file of at most `max_bytes` bytes. The type and the
/// size are taken from the opened file (so a file swapped after a check is not read), and the
/// read stops one byte past the cap (so a file that grows while it is read is refused too).
/// The error's text says why, for the caller to prefix with the path.
pub fn read_regular(path: &Path, max_bytes: u64) -> io::Result<Vec<u8>> {
    let (file, meta) = open_regular(path)?;
    if meta.len() > max_bytes {
        return Err(refused(too_large(meta.len(), max_bytes)));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(max_bytes + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max_bytes {
        return Err(refused(format!(
            "grew while it was read: {}",
            too_large(bytes.len() as u64, max_bytes)
        )));
    }
    Ok(bytes)
}

/// [`read_regular`] for text: the same checks, then UTF-8.
pub fn read_regular_text(path: &Path, max_bytes: u64) -> io::Result<String> {
    String::from_utf8(read_regular(path, max_bytes)?)
        .map_err(|_| refused("not UTF-8 text".to_string()))
}

/// Opens `path` for reading if it is a regular file, with its metadata (taken from the open
/// file). Opening a FIFO that no one writes to blocks until a writer comes, so the file is
/// opened non-blocking and then refused by its type; a regular file reads as usual.
pub fn open_regular(path: &Path) -> io::Result<(File, std::fs::Metadata)> {
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK);
    }
    let file = options.open(path)?;
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(refused(format!(
            "not a regular file (a {}); only regular files are read",
            file_kind(&meta.file_type())
        )));
    }
    Ok((file, meta))
}

/// What a file that is not a regular file is, in words.
pub fn file_kind(kind: &std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if kind.is_fifo() {
            return "FIFO";
        }
        if kind.is_char_device() {
            return "character device";
        }
        if kind.is_block_device() {
            return "block device";
        }
        if kind.is_socket() {
            return "socket";
        }
    }
    if kind.is_dir() {
        "directory"
    } else if kind.is_symlink() {
        "symbolic link"
    } else if kind.is_file() {
        "regular file"
    } else {
        "special file"
    }
}

fn too_large(len: u64, max_bytes: u64) -> String {
    format!("{len} bytes, more than the limit of {max_bytes} bytes")
}

fn refused(reason: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidData, reason)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("irs-files-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn regular_files_within_the_cap_are_read() {
        let d = dir("regular");
        let path = d.join("a.txt");
        std::fs::write(&path, b"hello").unwrap();
        assert_eq!(read_regular(&path, 5).unwrap(), b"hello");
        let e = read_regular(&path, 4).unwrap_err().to_string();
        assert_eq!(e, "5 bytes, more than the limit of 4 bytes");
        std::fs::write(&path, b"\xff").unwrap();
        assert_eq!(
            read_regular_text(&path, 5).unwrap_err().to_string(),
            "not UTF-8 text"
        );
        let _ = std::fs::remove_dir_all(&d);
    }

    #[cfg(unix)]
    #[test]
    fn devices_fifos_and_directories_are_refused_without_reading() {
        let d = dir("special");
        let fifo = d.join("fifo");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        for (path, kind) in [
            (Path::new("/dev/zero"), "character device"),
            (fifo.as_path(), "FIFO"),
            (d.as_path(), "directory"),
        ] {
            // A FIFO without a writer would block a plain open; /dev/zero would never end.
            let e = read_regular(path, 1 << 20).unwrap_err().to_string();
            assert_eq!(
                e,
                format!("not a regular file (a {kind}); only regular files are read")
            );
        }
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn the_caps_fit_the_largest_image_the_model_takes() {
        let side = irs_model::floorplan::MAX_IMAGE_SIDE as u64;
        // A binary P5 and a text P2 of 4096² pixels (255 and a space each) both fit.
        assert!(side * side + 20 <= MAX_IMAGE_FILE_BYTES);
        assert!(4 * side * side + 20 <= MAX_IMAGE_FILE_BYTES);
        assert!(MAX_IMAGE_FILE_BYTES.div_ceil(3) * 4 < MAX_SCENARIO_FILE_BYTES);
    }
}
