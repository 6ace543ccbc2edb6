use dhct_scan::FileFormat;

/// Recognises a file format from its first bytes. Returns `None` for anything else.
pub fn detect_format(bytes: &[u8]) -> Option<FileFormat> {
    detect_format_of_length(bytes, bytes.len() as u64)
}

/// [`detect_format`] from the first bytes (`head`, a few kB) of a file of `file_len`
/// bytes: a SPECS `.mul`/`.flm` has no magic, only a block structure that must fit the
/// whole file.
pub fn detect_format_of_length(bytes: &[u8], file_len: u64) -> Option<FileFormat> {
    if crate::sm4::looks_like_sm4(bytes) {
        return Some(FileFormat::RhkSm4);
    }
    if crate::sm4::sm3::looks_like_sm3(bytes) {
        return Some(FileFormat::RhkSm3);
    }
    let text_start = |magic: &str| {
        let skip_bom = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
        skip_bom.starts_with(magic.as_bytes())
    };
    if text_start(":NANONIS_VERSION:") {
        Some(FileFormat::NanonisSxm)
    } else if text_start("ISO/TC 201 SPM data transfer format") {
        Some(FileFormat::Iso28600)
    } else if text_start("Gwyddion Simple Field") {
        Some(FileFormat::Gsf)
    } else if bytes.starts_with(b"\x93NUMPY") {
        Some(FileFormat::Npy)
    } else if bytes.starts_with(b"II*\0") || bytes.starts_with(b"MM\0*") {
        // JPK's images are TIFFs with JPK's own tags.
        if crate::jpk::looks_like_jpk(bytes) {
            Some(FileFormat::Jpk)
        } else {
            Some(FileFormat::Tiff)
        }
    } else if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        Some(FileFormat::Png)
    } else if bytes.starts_with(crate::gwy::MAGIC) || bytes.starts_with(crate::gwy::OLD_MAGIC) {
        Some(FileFormat::Gwyddion)
    } else if text_start("[DataSet]") {
        Some(FileFormat::NanosurfNid)
    } else if crate::nanoscope::MAGICS
        .iter()
        .any(|m| bytes.starts_with(m))
    {
        // Not ISO 28600, whose `.spm` files start with "ISO/TC 201".
        Some(FileFormat::Nanoscope)
    } else if crate::createc::looks_like_createc(bytes) {
        Some(FileFormat::CreatecDat)
    } else if crate::matrix::looks_like_matrix(bytes) {
        Some(FileFormat::OmicronMatrix)
    } else if crate::wsxm::looks_like_wsxm(bytes) {
        Some(FileFormat::Wsxm)
    } else if crate::mul::looks_like_mul_of_length(bytes, file_len) {
        // Last: a MUL file has no magic of its own, only a plausible structure.
        Some(FileFormat::AarhusMul)
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recognises_magic_bytes_and_rejects_others() {
        assert_eq!(
            detect_format(b":NANONIS_VERSION:\n2\n"),
            Some(FileFormat::NanonisSxm)
        );
        assert_eq!(
            detect_format(b"ISO/TC 201 SPM data transfer format\r\n"),
            Some(FileFormat::Iso28600)
        );
        assert_eq!(
            detect_format(b"Gwyddion Simple Field 1.0\n"),
            Some(FileFormat::Gsf)
        );
        assert_eq!(detect_format(b"\x93NUMPY\x01\x00"), Some(FileFormat::Npy));
        assert_eq!(detect_format(b"II*\0\x08\0\0\0"), Some(FileFormat::Tiff));
        assert_eq!(detect_format(b"MM\0*\0\0\0\x08"), Some(FileFormat::Tiff));
        assert_eq!(
            detect_format(b"GWYPGwyContainer\0"),
            Some(FileFormat::Gwyddion)
        );
        assert_eq!(
            detect_format(b"[DataSet]\r\nVersion=2\r\n"),
            Some(FileFormat::NanosurfNid)
        );
        assert_eq!(
            detect_format(b"\\*File list\r\n\\Version: 0x05120130\r\n"),
            Some(FileFormat::Nanoscope)
        );
        assert_eq!(
            detect_format(b"[Paramco32]\r\nDAC-Type=20bit\r\n"),
            Some(FileFormat::CreatecDat)
        );
        assert_eq!(
            detect_format(b"ONTMATRX0101TLKB"),
            Some(FileFormat::OmicronMatrix)
        );
        assert_eq!(
            detect_format(b"WSxM file copyright UAM\r\nSxM Image file\r\n"),
            Some(FileFormat::Wsxm)
        );
        assert_eq!(
            detect_format(b"WSxM file copyright UAM\r\nIV curve file\r\n"),
            None
        );
        assert_eq!(detect_format(b""), None);
        assert_eq!(detect_format(b"hello world"), None);
        assert_eq!(detect_format(&[0xFF; 64]), None);
    }
}
