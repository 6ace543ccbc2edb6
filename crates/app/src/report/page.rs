//! A small HTML builder that escapes every piece of text: pages are built from elements,
//! text and table rows, never by pasting strings into markup. Only SVG that dhct drew
//! itself goes in unescaped ([`Html::trusted_svg`]).

/// The report's style sheet.
pub(crate) const STYLE: &str = "body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;max-width:1180px;margin:24px auto;padding:0 16px;color:#222}
h1{font-size:1.6em;margin-bottom:0}h2{border-bottom:1px solid #ccc;padding-bottom:4px;margin-top:2em}
.sub{color:#666;margin-top:4px}table{border-collapse:collapse;margin:8px 0 16px}td,th{border:1px solid #ddd;padding:3px 8px;text-align:right;font-variant-numeric:tabular-nums}
th{background:#f4f4f4}td:first-child,th:first-child{text-align:left}.grid{display:grid;grid-template-columns:repeat(auto-fill,minmax(520px,1fr));gap:18px}
figure{margin:0;border:1px solid #e4e4e4;padding:8px;background:#fff}figure svg{width:100%;height:auto}figure svg image{image-rendering:pixelated}
figcaption{font-size:.88em;color:#444;margin-top:6px}figcaption b{color:#222}.note{background:#fff8e0;border:1px solid #eed;padding:6px 10px}
.summary{background:#f3f7fb;border:1px solid #d5e2ef;padding:8px 14px}.summary h2{margin-top:.4em}.summary li{margin:3px 0}";

/// Escapes text for HTML and SVG (element content and quoted attribute values).
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// HTML under construction. Tag and attribute names are the code's constants; text and
/// attribute values are escaped.
#[derive(Default)]
pub struct Html {
    out: String,
}

impl Html {
    /// An empty builder.
    pub fn new() -> Html {
        Html::default()
    }

    /// `<tag name="value" …>`.
    pub fn open(&mut self, tag: &'static str, attributes: &[(&'static str, &str)]) -> &mut Html {
        self.out.push('<');
        self.out.push_str(tag);
        for (name, value) in attributes {
            self.out.push(' ');
            self.out.push_str(name);
            self.out.push_str("=\"");
            self.out.push_str(&escape(value));
            self.out.push('"');
        }
        self.out.push('>');
        self
    }

    /// `</tag>`.
    pub fn close(&mut self, tag: &'static str) -> &mut Html {
        self.out.push_str("</");
        self.out.push_str(tag);
        self.out.push_str(">\n");
        self
    }

    /// Escaped text.
    pub fn text(&mut self, text: &str) -> &mut Html {
        self.out.push_str(&escape(text));
        self
    }

    /// `<tag>text</tag>`.
    pub fn element(&mut self, tag: &'static str, text: &str) -> &mut Html {
        self.element_with(tag, &[], text)
    }

    /// `<tag attributes>text</tag>`.
    pub fn element_with(
        &mut self,
        tag: &'static str,
        attributes: &[(&'static str, &str)],
        text: &str,
    ) -> &mut Html {
        self.open(tag, attributes).text(text).close(tag)
    }

    /// A paragraph of class `class` that starts with a bold `lead`.
    pub fn note(&mut self, class: &str, lead: &str, text: &str) -> &mut Html {
        self.open("p", &[("class", class)])
            .element("b", lead)
            .text(" ")
            .text(text)
            .close("p")
    }

    /// A table with a header row and text cells.
    pub fn table<S: AsRef<str>>(&mut self, header: &[&str], rows: &[Vec<S>]) -> &mut Html {
        self.open("table", &[]).open("tr", &[]);
        for cell in header {
            self.element("th", cell);
        }
        self.close("tr");
        for row in rows {
            self.open("tr", &[]);
            for cell in row {
                self.element("td", cell.as_ref());
            }
            self.close("tr");
        }
        self.close("table")
    }

    /// A two-column table of (name, value) rows under the header `what`, `value`.
    pub fn pairs(&mut self, what: &str, rows: &[(String, String)]) -> &mut Html {
        let rows: Vec<Vec<&str>> = rows.iter().map(|(a, b)| vec![a.as_str(), b]).collect();
        self.table(&[what, "value"], &rows)
    }

    /// A bulleted list of text items.
    pub fn list<S: AsRef<str>>(&mut self, items: &[S]) -> &mut Html {
        self.open("ul", &[]);
        for item in items {
            self.element("li", item.as_ref());
        }
        self.close("ul")
    }

    /// An SVG document that dhct drew (its XML prolog, if any, dropped): inserted as is.
    pub fn trusted_svg(&mut self, svg: &str) -> &mut Html {
        let start = svg.find("<svg").unwrap_or(0);
        self.out.push_str(&svg[start..]);
        self
    }

    /// Appends another builder's HTML.
    pub fn append(&mut self, other: Html) -> &mut Html {
        self.out.push_str(&other.out);
        self
    }

    /// The HTML built.
    pub fn finish(self) -> String {
        self.out
    }
}

/// A whole page: `<!DOCTYPE html>`, head with `title` and [`STYLE`], `body`.
pub fn document(title: &str, body: Html) -> String {
    let mut page = Html::new();
    page.out.push_str("<!DOCTYPE html>\n");
    page.open("html", &[("lang", "en")])
        .open("head", &[])
        .open("meta", &[("charset", "utf-8")])
        .element("title", title)
        .open("style", &[]);
    page.out.push_str(STYLE);
    page.close("style").close("head").open("body", &[]);
    page.append(body);
    page.close("body").close("html");
    page.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_and_attributes_are_escaped() {
        let mut html = Html::new();
        html.element_with("p", &[("title", "a\"b<c>")], "x < y & 'z'")
            .table(&["<h>"], &[vec!["<td>".to_string()]]);
        let text = html.finish();
        assert!(text.contains("title=\"a&quot;b&lt;c&gt;\""), "{text}");
        assert!(text.contains("x &lt; y &amp; &#39;z&#39;"), "{text}");
        assert!(text.contains("<th>&lt;h&gt;</th>") && text.contains("<td>&lt;td&gt;</td>"));
        let page = document("t <1>", Html::new());
        assert!(page.starts_with("<!DOCTYPE html>") && page.contains("<title>t &lt;1&gt;</title>"));
    }
}
