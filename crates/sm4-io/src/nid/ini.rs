//! The INI-like text header of a Nanosurf `.nid` file: `[Section]` lines followed by
//! `Key=Value` lines.

/// The sections of the header in file order; within a section the first of repeated keys
/// wins.
#[derive(Debug, Default)]
pub struct Ini {
    sections: Vec<(String, Vec<(String, String)>)>,
}

impl Ini {
    /// Parses `text` (lines end in LF or CR LF; blank lines and text before the first
    /// section are ignored; a line without `=` is ignored).
    pub fn parse(text: &str) -> Ini {
        let mut sections: Vec<(String, Vec<(String, String)>)> = Vec::new();
        for line in text.lines() {
            let line = line.trim_end_matches('\r');
            if let Some(name) = line
                .trim()
                .strip_prefix('[')
                .and_then(|l| l.strip_suffix(']'))
            {
                sections.push((name.to_string(), Vec::new()));
            } else if let (Some((_, entries)), Some((key, value))) =
                (sections.last_mut(), line.split_once('='))
            {
                entries.push((key.trim().to_string(), value.trim().to_string()));
            }
        }
        Ini { sections }
    }

    /// The entries of section `name` (exact, case-sensitive), if present.
    pub fn section(&self, name: &str) -> Option<&[(String, String)]> {
        self.sections
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, e)| e.as_slice())
    }

    /// The value of `key` in section `name`.
    pub fn get(&self, section: &str, key: &str) -> Option<&str> {
        self.section(section)?
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sections_and_keys() {
        let ini = Ini::parse("junk\r\n[A]\r\nx=1\r\nx=2\r\n\r\n[B\\C]\ny = two words \nnoequals\n");
        assert_eq!(ini.get("A", "x"), Some("1"));
        assert_eq!(ini.get("B\\C", "y"), Some("two words"));
        assert_eq!(ini.get("B", "y"), None);
        assert_eq!(ini.section("B\\C").map(|s| s.len()), Some(1));
    }
}
