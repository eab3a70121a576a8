//! The report as one model, rendered to Markdown and to a self-contained HTML page, so the two
//! cannot say different things.
use std::fmt::Write as _;

/// The largest SVG chart the HTML page embeds; a larger one (a chart with many dense curves) is
/// shown from its file beside the page, so the page stays light.
pub(crate) const INLINE_SVG_MAX_BYTES: usize = 40_000;

#[derive(Debug, Clone, PartialEq)]
pub enum Block {
    Heading {
        level: usize,
        text: String,
    },
    Paragraph(String),
    /// An SVG chart: the Markdown links `file`; the HTML page embeds `svg`, or links `file`
    /// when the chart is not `inline` (detail charts, to keep the page light).
    Figure {
        file: String,
        svg: String,
        caption: String,
        inline: bool,
    },
    Table {
        header: Vec<String>,
        rows: Vec<Vec<String>>,
    },
    /// Lines shown as a list.
    Lines(Vec<String>),
    /// A chart written beside the page and shown from its file (`<img>`), so a page with many
    /// charts stays light.
    Image {
        file: String,
        caption: String,
    },
    /// A video: the HTML page plays `video` (with `poster`, if any, shown before it plays); the
    /// Markdown page shows the GIF `gif` (else the poster, else nothing) and links the video.
    /// `timing`: the episode's length (s) and the video's frames per second, kept on the page for
    /// checks.
    Video {
        video: String,
        gif: Option<String>,
        poster: Option<String>,
        caption: String,
        timing: Option<(f64, f64)>,
    },
}

impl Block {
    /// A report clip: its MP4 with its poster, its GIF, and the episode's timing.
    pub(crate) fn clip(clip: &super::videos::Clip) -> Block {
        Block::Video {
            video: clip.video.clone(),
            gif: clip.gif.clone(),
            poster: Some(clip.poster.clone()),
            caption: clip.caption.clone(),
            timing: Some((clip.duration, clip.fps)),
        }
    }
}

#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Document {
    pub(crate) title: String,
    pub blocks: Vec<Block>,
}

impl Document {
    pub fn new(title: &str) -> Document {
        Document { title: title.to_string(), blocks: Vec::new() }
    }

    pub fn heading(&mut self, level: usize, text: impl Into<String>) {
        self.blocks.push(Block::Heading { level, text: text.into() });
    }

    pub(crate) fn paragraph(&mut self, text: impl Into<String>) {
        self.blocks.push(Block::Paragraph(text.into()));
    }

    /// An SVG chart the page embeds, or, when it is larger than [`INLINE_SVG_MAX_BYTES`], shows
    /// from its file like [`Document::image`].
    pub fn figure(&mut self, file: impl Into<String>, svg: String, caption: impl Into<String>) {
        self.blocks.push(Block::Figure { file: file.into(), svg, caption: caption.into(), inline: true });
    }

    /// A chart written beside the page, shown from its file rather than embedded.
    pub(crate) fn image(&mut self, file: impl Into<String>, caption: impl Into<String>) {
        self.blocks.push(Block::Image { file: file.into(), caption: caption.into() });
    }

    /// A chart written beside the page and linked from it, not embedded.
    pub(crate) fn linked_figure(&mut self, file: impl Into<String>, caption: impl Into<String>) {
        self.blocks.push(Block::Figure {
            file: file.into(),
            svg: String::new(),
            caption: caption.into(),
            inline: false,
        });
    }

    pub fn table(&mut self, header: &[&str], rows: Vec<Vec<String>>) {
        self.blocks.push(Block::Table { header: header.iter().map(|h| h.to_string()).collect(), rows });
    }

    pub fn lines(&mut self, lines: Vec<String>) {
        self.blocks.push(Block::Lines(lines));
    }

    pub(crate) fn video(&mut self, clip: &super::videos::Clip) {
        self.blocks.push(Block::clip(clip));
    }

    /// Puts `blocks` before the block at `index` (what was written later but is read first).
    pub(crate) fn insert(&mut self, index: usize, blocks: Vec<Block>) {
        self.blocks.splice(index..index, blocks);
    }

    pub(crate) fn to_markdown(&self) -> String {
        let mut md = format!("# {}\n\n", self.title);
        for block in &self.blocks {
            match block {
                Block::Heading { level, text } => {
                    let _ = writeln!(md, "{} {text}\n", "#".repeat(level + 1));
                }
                Block::Paragraph(text) => {
                    let _ = writeln!(md, "{text}\n");
                }
                Block::Figure { file, caption, .. } | Block::Image { file, caption } => {
                    let _ = writeln!(md, "![{caption}]({file})\n");
                }
                Block::Table { header, rows } => {
                    let _ = writeln!(md, "| {} |\n|{}", header.join(" | "), "---|".repeat(header.len()));
                    for row in rows {
                        let _ = writeln!(md, "| {} |", row.join(" | "));
                    }
                    md.push('\n');
                }
                Block::Lines(lines) => {
                    for line in lines {
                        let _ = writeln!(md, "- {line}");
                    }
                    md.push('\n');
                }
                Block::Video { video, gif, poster, caption, .. } => {
                    match (gif, poster) {
                        (Some(gif), _) => {
                            let _ = writeln!(md, "![{caption}]({gif})\n");
                        }
                        (None, Some(poster)) => {
                            let _ = writeln!(md, "[![{caption}]({poster})]({video})\n");
                        }
                        (None, None) => {}
                    }
                    let _ = writeln!(md, "{caption}. [The whole episode (MP4)]({video})\n");
                }
            }
        }
        md
    }

    pub(crate) fn to_html(&self) -> String {
        let mut body = format!("<h1>{}</h1>\n", escape(&self.title));
        for block in &self.blocks {
            match block {
                Block::Heading { level, text } => {
                    let _ = writeln!(body, "<h{n}>{}</h{n}>", escape(text), n = level + 1);
                }
                Block::Paragraph(text) => {
                    let _ = writeln!(body, "<p>{}</p>", escape(text));
                }
                Block::Figure { svg, caption, inline: true, .. } if svg.len() <= INLINE_SVG_MAX_BYTES => {
                    let _ = writeln!(body, "<figure>{svg}<figcaption>{}</figcaption></figure>", escape(caption));
                }
                Block::Image { file, caption } | Block::Figure { file, caption, inline: true, .. } => {
                    let _ = writeln!(
                        body,
                        "<figure><img src=\"{}\" alt=\"{}\"><figcaption>{}</figcaption></figure>",
                        escape(file),
                        escape(caption),
                        escape(caption)
                    );
                }
                Block::Figure { file, caption, inline: false, .. } => {
                    let _ = writeln!(body, "<p><a href=\"{}\">{}</a></p>", escape(file), escape(caption));
                }
                Block::Table { header, rows } => {
                    body.push_str("<div class=\"wide\"><table><tr>");
                    for h in header {
                        let _ = write!(body, "<th>{}</th>", escape(h));
                    }
                    body.push_str("</tr>");
                    for row in rows {
                        body.push_str("<tr>");
                        for c in row {
                            let _ = write!(body, "<td>{}</td>", escape(c));
                        }
                        body.push_str("</tr>");
                    }
                    body.push_str("</table></div>\n");
                }
                Block::Lines(lines) => {
                    body.push_str("<ul>");
                    for line in lines {
                        let _ = write!(body, "<li>{}</li>", escape(line));
                    }
                    body.push_str("</ul>\n");
                }
                Block::Video { video, poster, caption, timing, .. } => {
                    let poster = poster.as_ref().map_or(String::new(), |p| format!(" poster=\"{}\"", escape(p)));
                    let timing = timing
                        .map_or(String::new(), |(d, fps)| format!(" data-duration=\"{d:.3}\" data-fps=\"{fps:.3}\""));
                    let _ = writeln!(
                        body,
                        "<figure><video controls muted playsinline preload=\"metadata\"{poster} src=\"{}\"{timing}>\
                         </video><figcaption>{}</figcaption></figure>",
                        escape(video),
                        escape(caption)
                    );
                }
            }
        }
        format!(
            "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{}</title><style>\
             body{{font-family:sans-serif;max-width:1000px;margin:2em auto;color:#222}}\
             table{{border-collapse:collapse;margin:1em 0}}td,th{{border:1px solid #bbb;padding:3px 8px;text-align:right}}\
             th{{background:#eee}}figure{{margin:1em 0}}figcaption{{color:#555;font-size:90%}}\
             .wide{{overflow-x:auto}}svg,video,img{{max-width:100%;height:auto}}li{{overflow-wrap:anywhere}}</style></head><body>\n\
             {body}</body></html>\n",
            escape(&self.title)
        )
    }
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every text of the model appears in both renderings (escaped in HTML).
    #[test]
    fn markdown_and_html_carry_the_same_content() {
        let mut d = Document::new("report");
        d.heading(1, "minitaur");
        d.paragraph("5 episodes per policy <seeded>");
        d.figure("a.svg", "<svg id=\"chart\"></svg>".into(), "evaluation curves");
        d.table(&["policy", "return"], vec![vec!["td3".into(), "2.9 ± 0.1".into()], vec!["sac".into(), "10".into()]]);
        d.lines(vec!["`runs/a`: td3 seed 0".into()]);
        let (md, html) = (d.to_markdown(), d.to_html());
        for text in
            ["minitaur", "evaluation curves", "policy", "return", "td3", "2.9 ± 0.1", "sac", "`runs/a`: td3 seed 0"]
        {
            assert!(md.contains(text) && html.contains(text), "{text}");
        }
        assert!(md.contains("5 episodes per policy <seeded>") && html.contains("5 episodes per policy &lt;seeded&gt;"));
        assert!(md.contains("![evaluation curves](a.svg)") && html.contains("<svg id=\"chart\"></svg>"));
        assert!(md.contains("## minitaur") && html.contains("<h2>minitaur</h2>"));
        assert_eq!(md.matches("| td3 |").count(), 1);
        assert_eq!(html.matches("<tr>").count(), 3);
    }

    /// A chart up to the limit is embedded; a larger one is shown from its file, with its caption.
    #[test]
    fn a_large_chart_is_shown_from_its_file_not_embedded() {
        let small = format!("<svg>{}</svg>", "x".repeat(INLINE_SVG_MAX_BYTES - 11));
        let large = format!("<svg>{}</svg>", "y".repeat(INLINE_SVG_MAX_BYTES));
        let mut d = Document::new("report");
        d.figure("small.svg", small.clone(), "small chart");
        d.figure("large.svg", large.clone(), "large chart");
        let (md, html) = (d.to_markdown(), d.to_html());
        assert_eq!(small.len(), INLINE_SVG_MAX_BYTES);
        assert!(html.contains(&small) && !html.contains("src=\"small.svg\""));
        assert!(!html.contains(&large));
        assert!(html.contains("<img src=\"large.svg\" alt=\"large chart\"><figcaption>large chart</figcaption>"));
        assert!(md.contains("![small chart](small.svg)") && md.contains("![large chart](large.svg)"));
    }
}
