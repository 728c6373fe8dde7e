//! Self-contained HTML reports: a command's `report.md` rendered to `report.html` with its SVG
//! figures inlined, so the page reads offline in any browser (no network, no separate files).
//!
//! The Markdown is rendered by pulldown-cmark (CommonMark plus tables); an image whose source
//! is an SVG staged beside the report is replaced by the SVG itself. The page carries a small
//! stylesheet (tables with borders, figures scaled to the page width) and nothing else: no
//! script, no external font or style.
//!
//! ```
//! let html = cpm_report::html::render("Demo", "# Title\n\n| a | b |\n|---|---|\n| 1 | 2 |\n\n![f](f.svg)\n",
//!     |name| (name == "f.svg").then(|| "<svg xmlns=\"http://www.w3.org/2000/svg\"></svg>".to_string()));
//! assert!(html.contains("<table>") && html.contains("<svg") && !html.contains("f.svg\""));
//! ```
use pulldown_cmark::{html, Event, Options, Parser, Tag, TagEnd};

const STYLE: &str = "body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;line-height:1.45;color:#222}\
table{border-collapse:collapse;margin:1em 0;font-size:0.9em}th,td{border:1px solid #bbb;padding:3px 8px;text-align:left}\
th{background:#eee}code{background:#f3f3f3;padding:0 3px}figure{margin:1em 0}figure svg{max-width:100%;height:auto}\
figcaption{font-size:0.85em;color:#555}.missing{color:#a00}";

/// Renders `markdown` as a complete HTML page titled `title`; `svg(name)` gives the SVG text of
/// an image source (`None`: the image is shown as a note that it is missing, never fetched).
pub fn render(title: &str, markdown: &str, svg: impl Fn(&str) -> Option<String>) -> String {
    let parser = Parser::new_ext(markdown, Options::ENABLE_TABLES);
    let mut events: Vec<Event<'_>> = Vec::new();
    let mut in_image: Option<(String, String)> = None;
    for ev in parser {
        match ev {
            Event::Start(Tag::Image { dest_url, .. }) => {
                in_image = Some((dest_url.to_string(), String::new()));
            }
            Event::End(TagEnd::Image) => {
                if let Some((src, alt)) = in_image.take() {
                    let body = match svg(&src) {
                        Some(s) => strip_xml_prolog(&s).to_string(),
                        None => format!(
                            "<p class=\"missing\">figure {} is not in this report</p>",
                            escape(&src)
                        ),
                    };
                    events.push(Event::Html(
                        format!(
                            "<figure>{body}<figcaption>{}</figcaption></figure>",
                            escape(&alt)
                        )
                        .into(),
                    ));
                }
            }
            Event::Text(t) if in_image.is_some() => {
                if let Some((_, alt)) = in_image.as_mut() {
                    alt.push_str(&t);
                }
            }
            e if in_image.is_some() => drop(e),
            e => events.push(e),
        }
    }
    let mut body = String::new();
    html::push_html(&mut body, events.into_iter());
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n<title>{}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n{body}</body>\n</html>\n",
        escape(title)
    )
}

/// The `report.html` page of a command's `markdown`, titled `title`, with the SVG `figures`
/// (file name, SVG text) that sit beside the report inlined: where the Markdown shows them as
/// images, and the others, in the order given, in a closing "Figures" section. Only plain
/// `.svg` names are looked up (no path, no `..`).
pub fn report_page(title: &str, markdown: &str, figures: &[(String, String)]) -> String {
    let mut md = markdown.to_string();
    let others: Vec<&str> = figures
        .iter()
        .map(|(n, _)| n.as_str())
        .filter(|n| !md.contains(&format!("]({n})")))
        .collect();
    if !others.is_empty() {
        let images: String = others.iter().map(|n| format!("![{n}]({n})\n\n")).collect();
        // Into the report's own "Figures" section when it has one (at its end), else a new one.
        match md.find("\n## Figures\n") {
            Some(at) => {
                let body = at + "\n## Figures\n".len();
                let end = md[body..].find("\n## ").map_or(md.len(), |e| body + e);
                md.insert_str(end, &format!("\n{images}"));
            }
            None => {
                md.push_str("\n## Figures\n\n");
                md.push_str(&images);
            }
        }
    }
    render(title, &md, |name| {
        if !name.ends_with(".svg") || name.contains('/') || name.contains("..") {
            return None;
        }
        figures
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, svg)| svg.clone())
    })
}

fn strip_xml_prolog(s: &str) -> &str {
    let s = s.trim_start();
    if s.starts_with("<?xml") {
        s.find("?>").map_or(s, |i| s[i + 2..].trim_start())
    } else {
        s
    }
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn figures_are_inlined_and_nothing_is_fetched() {
        let md = "# R\n\nSome **bold** text.\n\n![residuals](residuals.svg)\n\n![gone](gone.svg)\n\n![web](https://example.com/x.svg)\n";
        let html = render("R <1>", md, |n| {
            (n == "residuals.svg").then(|| {
                "<?xml version=\"1.0\"?><svg width=\"10\" height=\"10\"><circle r=\"1\"/></svg>"
                    .into()
            })
        });
        assert!(html.contains("<title>R &lt;1&gt;</title>"));
        assert!(html.contains("<strong>bold</strong>"));
        assert!(html.contains("<svg width=\"10\""));
        assert!(!html.contains("<?xml"));
        assert!(html.contains("figure gone.svg is not in this report"));
        // No resource is referenced by URL: no img, no link, no script.
        for tag in ["<img", "<script", "<link", "src=", "href=\"http"] {
            assert!(!html.contains(tag), "{tag} in {html}");
        }
    }

    #[test]
    fn one_figures_section() {
        let svg = |n: &str| (n.to_string(), "<svg width=\"1\"></svg>".to_string());
        let md = "# R\n\n## Figures\n\n- `a.svg`: a.\n\n## Notes\n\nEnd.\n";
        let html = report_page("R", md, &[svg("a.svg"), svg("b.svg")]);
        assert_eq!(html.matches(">Figures</h2>").count(), 1, "{html}");
        assert_eq!(html.matches("<svg").count(), 2);
        // The figures sit in that section, before the next one.
        assert!(html.find("<svg").unwrap() < html.find(">Notes</h2>").unwrap());
        let html = report_page("R", "# R\n", &[svg("a.svg")]);
        assert_eq!(html.matches(">Figures</h2>").count(), 1);
    }
}
