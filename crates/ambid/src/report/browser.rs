//! Checks a rendered report in a real browser (headless Chromium), for tests and users.
//!
//! [`browser_check`] loads the HTML file twice: once to take a full-page screenshot and once to
//! dump the rendered DOM, both with console logging on. It counts the `<svg>` elements of the
//! rendered DOM and those that are empty (no drawn element, or zero width/height), lists
//! references to external resources in the rendered DOM, and collects console messages.
//! When Chromium is not installed it returns [`BrowserCheck::Unavailable`] instead of failing,
//! so tests can skip.
//!
//! Console messages: headless Chromium logs page console messages as `INFO:CONSOLE` lines
//! whatever their level (a `console.error` looks like a `console.log`), and does not log failed
//! resource loads of a `file://` page at all. A report has no script, so *every* console line
//! (uncaught errors, CSP or parse complaints) counts as an error; failed loads are caught
//! statically instead, by the external-reference scan of the rendered DOM.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// Where Chromium is looked for (overridden by the environment variable `AMBID_CHROMIUM`).
pub const CHROMIUM: &str = "/usr/bin/chromium";

/// A screenshot of at most this many bytes counts as trivial: a blank white 1280×8000 page is
/// about 46 kB as PNG (Chromium 156), a report with only its header about 65 kB.
pub const MIN_SCREENSHOT_BYTES: u64 = 55_000;

/// How long one Chromium run may take before it is killed.
const TIMEOUT: Duration = Duration::from_secs(90);

/// How many times a Chromium run that hung (was killed after [`TIMEOUT`]) is started again with
/// a fresh profile. Headless Chromium occasionally never exits after writing its screenshot on
/// a loaded machine (seen once in CI with the test suite on both cores); a crash or a non-zero
/// exit is never retried, and every retry is logged on stderr.
const HANG_RETRIES: usize = 1;

/// The outcome of [`browser_check`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BrowserCheck {
    /// No browser available: nothing was checked (tests should skip, saying why).
    Unavailable {
        /// Why, e.g. `"/usr/bin/chromium not installed"`.
        reason: String,
    },
    /// The report was loaded and rendered by Chromium.
    Checked(BrowserCounts),
}

/// What Chromium saw.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct BrowserCounts {
    /// `<svg>` elements in the rendered DOM.
    pub svgs: usize,
    /// `<svg>` elements without any drawn element (path, line, polyline, polygon, rect, circle,
    /// ellipse, text outside `<defs>`) or with a zero or missing width/height attribute.
    pub empty_svgs: usize,
    /// Console messages (any level: a report has no script) and failed resource loads, one
    /// log line each.
    pub console_errors: Vec<String>,
    /// References to resources outside the document in the rendered DOM (`src`, `href` or
    /// `url(…)` not pointing at a `#fragment`, `<script>`, `<link>`, `@import`, …).
    pub external_refs: Vec<String>,
    /// Size of the full-page screenshot (PNG) in bytes; 0 when none was written.
    pub screenshot_bytes: u64,
    /// Size of the rendered DOM in bytes.
    pub dom_bytes: usize,
    /// Elements whose box ends right of the page (1280 px wide window), and table wrappers whose
    /// table is wider than they are (columns hidden behind a scroll bar), from the layout run.
    pub overflowing: Vec<String>,
    /// The id of the first `<section>` of the page (the report's summary comes first).
    pub first_section: String,
    /// Pieces of the visible text that look like Rust debug output (`Some(`, `None`, `::`).
    pub debug_text: Vec<String>,
}

impl BrowserCheck {
    /// The counts, if the check ran.
    pub fn counts(&self) -> Option<&BrowserCounts> {
        match self {
            BrowserCheck::Checked(c) => Some(c),
            BrowserCheck::Unavailable { .. } => None,
        }
    }

    /// What is wrong with the rendered page (empty when it looks fine, or when nothing was
    /// checked): no SVG, empty SVGs, console messages, external resources, a missing or tiny
    /// screenshot.
    pub fn problems(&self) -> Vec<String> {
        let Some(c) = self.counts() else {
            return Vec::new();
        };
        let mut p = Vec::new();
        if c.svgs == 0 {
            p.push("no <svg> in the rendered page".to_string());
        }
        if c.empty_svgs > 0 {
            p.push(format!(
                "{} of {} <svg> elements are empty",
                c.empty_svgs, c.svgs
            ));
        }
        for e in &c.console_errors {
            p.push(format!("console: {e}"));
        }
        for e in &c.external_refs {
            p.push(format!("external resource: {e}"));
        }
        for e in &c.overflowing {
            p.push(format!("wider than the page: {e}"));
        }
        for e in &c.debug_text {
            p.push(format!("debug text on the page: {e}"));
        }
        if c.screenshot_bytes <= MIN_SCREENSHOT_BYTES {
            p.push(format!(
                "screenshot missing or trivial ({} bytes)",
                c.screenshot_bytes
            ));
        }
        p
    }
}

/// Loads `html_path` in headless Chromium and reports what it rendered (see [`BrowserCheck`]).
///
/// Errors are for failures of the check itself (file missing, Chromium crashed or timed out);
/// a missing Chromium is `Ok(BrowserCheck::Unavailable { .. })`.
pub fn browser_check(html_path: &Path) -> Result<BrowserCheck, String> {
    let chromium = std::env::var_os("AMBID_CHROMIUM")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(CHROMIUM));
    if !chromium.is_file() {
        return Ok(BrowserCheck::Unavailable {
            reason: format!("{} not installed", chromium.display()),
        });
    }
    let html = fs::canonicalize(html_path)
        .map_err(|e| format!("cannot open {}: {e}", html_path.display()))?;
    let url = file_url(&html);
    let work = TempDir::new()?;

    // (a) Full-page screenshot.
    let shot = work.0.join("screenshot.png");
    let run_a = run_chromium(
        &chromium,
        &work.0,
        "shot",
        &[
            format!("--screenshot={}", shot.display()),
            "--window-size=1280,8000".into(),
            "--hide-scrollbars".into(),
            "--enable-logging=stderr".into(),
            "--v=0".into(),
            url.clone(),
        ],
    )?;
    let screenshot_bytes = fs::metadata(&shot).map(|m| m.len()).unwrap_or(0);

    // (b) + (c) Rendered DOM, with console logging.
    let run_b = run_chromium(
        &chromium,
        &work.0,
        "dom",
        &[
            "--dump-dom".into(),
            "--enable-logging=stderr".into(),
            "--v=0".into(),
            url,
        ],
    )?;
    // (d) Layout: a copy of the page with a script at the end of its body that measures every
    // element against the window width and writes the findings into the DOM.
    let probe = work.0.join("layout.html");
    let page =
        fs::read_to_string(&html).map_err(|e| format!("cannot read {}: {e}", html.display()))?;
    let with_probe = match page.rfind("</body>") {
        Some(i) => format!("{}{LAYOUT_PROBE}{}", &page[..i], &page[i..]),
        None => format!("{page}{LAYOUT_PROBE}"),
    };
    fs::write(&probe, with_probe).map_err(|e| format!("cannot write the layout copy: {e}"))?;
    let run_c = run_chromium(
        &chromium,
        &work.0,
        "layout",
        &[
            "--dump-dom".into(),
            "--window-size=1280,8000".into(),
            "--hide-scrollbars".into(),
            file_url(&probe),
        ],
    )?;
    let layout = parse_layout(&run_c.stdout)?;
    let (svgs, empty_svgs) = count_svgs(&run_b.stdout);
    let name = html
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    // Both runs log the same messages; keep each message once (ignoring the pid/time prefix).
    let mut console_errors: Vec<String> = Vec::new();
    for e in console_errors_in(&run_a.stderr, &name)
        .into_iter()
        .chain(console_errors_in(&run_b.stderr, &name))
    {
        let key = |l: &str| l.split_once("] ").map(|(_, m)| m.to_string());
        if !console_errors.iter().any(|k| key(k) == key(&e)) {
            console_errors.push(e);
        }
    }
    Ok(BrowserCheck::Checked(BrowserCounts {
        svgs,
        empty_svgs,
        console_errors,
        external_refs: external_refs(&run_b.stdout),
        screenshot_bytes,
        dom_bytes: run_b.stdout.len(),
        overflowing: layout.overflow,
        first_section: layout.first,
        debug_text: debug_text(&layout.text),
    }))
}

/// The layout probe (see [`browser_check`], run (d)); its result is JSON in `<pre id="ambid-layout">`.
const LAYOUT_PROBE: &str = r#"<script>
(function(){
  var W = document.documentElement.clientWidth, bad = [];
  var all = document.querySelectorAll('body *');
  for (var k = 0; k < all.length; k++) {
    var e = all[k];
    // inside an <svg> nothing is drawn beyond the svg's own box (clipped): measure the svg only
    if (e.tagName.toLowerCase() !== 'svg' && e.closest('svg')) continue;
    var r = e.getBoundingClientRect();
    var name = e.tagName.toLowerCase() + (e.id ? '#' + e.id : '');
    if (r.width > 0 && r.right > W + 1) bad.push(name + ' ends at ' + Math.round(r.right) + ' px of ' + W);
    if (e.classList && e.classList.contains('table-wrap') && e.scrollWidth > e.clientWidth + 1)
      bad.push(name + ': table ' + e.scrollWidth + ' px wide in ' + e.clientWidth + ' px');
  }
  var first = document.querySelector('main section');
  var p = document.createElement('pre');
  p.id = 'ambid-layout';
  p.textContent = JSON.stringify({width: W, overflow: bad.slice(0, 40),
    first: first ? first.id : '', text: document.body.innerText});
  document.body.appendChild(p);
})();
</script>
"#;

/// What the layout probe found.
#[derive(serde::Deserialize)]
struct Layout {
    overflow: Vec<String>,
    first: String,
    text: String,
}

fn parse_layout(dom: &str) -> Result<Layout, String> {
    let start = dom
        .find("<pre id=\"ambid-layout\">")
        .ok_or("the layout probe wrote no result (script did not run)")?;
    let body = &dom[start + "<pre id=\"ambid-layout\">".len()..];
    let end = body.find("</pre>").ok_or("unterminated layout result")?;
    let json = body[..end]
        .replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&nbsp;", "\u{a0}")
        .replace("&amp;", "&");
    serde_json::from_str(&json).map_err(|e| format!("unreadable layout result: {e}"))
}

/// Pieces of `text` that look like Rust debug output: `Some(`, the word `None`, `::`.
pub(crate) fn debug_text(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for pat in ["Some(", "None", "::"] {
        for (i, _) in text.match_indices(pat) {
            if pat == "None" {
                let before = text[..i].chars().next_back();
                let after = text[i + 4..].chars().next();
                let word = |c: Option<char>| c.is_some_and(|c| c.is_alphanumeric() || c == '_');
                if word(before) || word(after) {
                    continue;
                }
            }
            let from = text[..i].char_indices().rev().nth(40).map_or(0, |(j, _)| j);
            let to = text[i..]
                .char_indices()
                .nth(40)
                .map_or(text.len(), |(j, _)| i + j);
            out.push(text[from..to].replace('\n', " "));
        }
    }
    out
}

/// Output of one Chromium run.
#[derive(Debug)]
struct RunOutput {
    stdout: String,
    stderr: String,
}

/// A temporary directory removed on drop.
struct TempDir(PathBuf);

static COUNTER: AtomicUsize = AtomicUsize::new(0);

impl TempDir {
    fn new() -> Result<Self, String> {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0);
        let dir = std::env::temp_dir().join(format!(
            "ambid-browser-{}-{nanos}-{}",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        fs::create_dir_all(&dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
        Ok(TempDir(dir))
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.0);
    }
}

/// Why one Chromium run failed.
enum RunError {
    /// Killed after its time limit.
    Hung(String),
    /// Could not start, or exited with an error.
    Failed(String),
}

/// [`run_chromium_once`], started again (at most [`HANG_RETRIES`] times) when it hangs.
fn run_chromium(
    chromium: &Path,
    work: &Path,
    tag: &str,
    args: &[String],
) -> Result<RunOutput, String> {
    run_chromium_within(chromium, work, tag, args, TIMEOUT)
}

/// [`run_chromium`] with the time limit of one run given.
fn run_chromium_within(
    chromium: &Path,
    work: &Path,
    tag: &str,
    args: &[String],
    timeout: Duration,
) -> Result<RunOutput, String> {
    let mut attempt = 0;
    loop {
        let attempt_tag = if attempt == 0 {
            tag.to_string()
        } else {
            format!("{tag}-retry{attempt}")
        };
        match run_chromium_once(chromium, work, &attempt_tag, args, timeout) {
            Ok(out) => return Ok(out),
            Err(RunError::Hung(msg)) if attempt < HANG_RETRIES => {
                eprintln!("browser check: {msg}; starting it again with a fresh profile");
                attempt += 1;
            }
            Err(RunError::Hung(msg) | RunError::Failed(msg)) => return Err(msg),
        }
    }
}

/// Runs Chromium headless with a fresh profile; stdout and stderr go to files (no pipe can
/// fill up), the run is killed after `timeout`.
fn run_chromium_once(
    chromium: &Path,
    work: &Path,
    tag: &str,
    args: &[String],
    timeout: Duration,
) -> Result<RunOutput, RunError> {
    let fail = RunError::Failed;
    let profile = work.join(format!("profile-{tag}"));
    fs::create_dir_all(&profile).map_err(|e| fail(format!("cannot create profile dir: {e}")))?;
    let out_path = work.join(format!("{tag}.stdout"));
    let err_path = work.join(format!("{tag}.stderr"));
    let out = fs::File::create(&out_path).map_err(|e| fail(format!("temp file: {e}")))?;
    let err = fs::File::create(&err_path).map_err(|e| fail(format!("temp file: {e}")))?;
    let mut child = Command::new(chromium)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(args)
        .stdin(Stdio::null())
        .stdout(out)
        .stderr(err)
        .spawn()
        .map_err(|e| fail(format!("cannot start {}: {e}", chromium.display())))?;
    let start = Instant::now();
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if start.elapsed() > timeout => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(RunError::Hung(format!(
                    "chromium ({tag}) timed out after {timeout:?}"
                )));
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(20)),
            Err(e) => return Err(fail(format!("waiting for chromium: {e}"))),
        }
    };
    let stdout = String::from_utf8_lossy(&fs::read(&out_path).unwrap_or_default()).into_owned();
    let stderr = String::from_utf8_lossy(&fs::read(&err_path).unwrap_or_default()).into_owned();
    if !status.success() {
        let tail: Vec<&str> = stderr.lines().rev().take(8).collect();
        return Err(fail(format!(
            "chromium ({tag}) failed with {status}: {}",
            tail.into_iter().rev().collect::<Vec<_>>().join(" | ")
        )));
    }
    Ok(RunOutput { stdout, stderr })
}

/// `file://` URL of an absolute path (percent-encoding everything but unreserved characters).
fn file_url(path: &Path) -> String {
    let mut url = String::from("file://");
    for b in path.to_string_lossy().bytes() {
        if b.is_ascii_alphanumeric() || b"/-._~".contains(&b) {
            url.push(b as char);
        } else {
            url.push_str(&format!("%{b:02X}"));
        }
    }
    url
}

/// Error lines in Chromium's log: every page console message (see the module documentation),
/// failed or refused resource loads, and any error-level line naming the page.
pub(crate) fn console_errors_in(stderr: &str, file_name: &str) -> Vec<String> {
    stderr
        .lines()
        .filter(|l| {
            let console = l.contains(":CONSOLE");
            let load = l.contains("Failed to load resource")
                || l.contains("Not allowed to load local resource")
                || l.contains("Refused to")
                || l.contains("net::ERR_");
            let error_about_page =
                l.contains(":ERROR:") && !file_name.is_empty() && l.contains(file_name);
            console || load || error_about_page
        })
        .map(|l| l.trim().to_string())
        .collect()
}

/// References to resources outside the document in a DOM dump.
pub(crate) fn external_refs(dom: &str) -> Vec<String> {
    let lower = dom.to_ascii_lowercase();
    let mut out = Vec::new();
    for tag in [
        "<script", "<link", "<iframe", "<object", "<embed", "@import",
    ] {
        let mut rest = lower.as_str();
        while let Some(i) = rest.find(tag) {
            let snippet: String = rest[i..].chars().take(80).collect();
            out.push(snippet);
            rest = &rest[i + tag.len()..];
        }
    }
    for key in [" src=", " href=", " xlink:href=", "url("] {
        let mut rest = lower.as_str();
        while let Some(i) = rest.find(key) {
            let value = rest[i + key.len()..].trim_start_matches(['"', '\'', ' ']);
            if !value.starts_with('#') {
                let snippet: String = rest[i..].chars().take(80).collect();
                out.push(snippet.trim().to_string());
            }
            rest = &rest[i + key.len()..];
        }
    }
    out
}

/// Counts `<svg>` elements in a DOM dump and those that are empty.
pub(crate) fn count_svgs(dom: &str) -> (usize, usize) {
    let lower = dom.to_ascii_lowercase();
    let mut rest = lower.as_str();
    let (mut n, mut empty) = (0usize, 0usize);
    while let Some(start) = rest.find("<svg") {
        let after = &rest[start..];
        let next_char = after.as_bytes().get(4).copied().unwrap_or(b'>');
        if !(next_char == b' ' || next_char == b'>' || next_char == b'\n' || next_char == b'\t') {
            rest = &after[4..];
            continue;
        }
        n += 1;
        let open_end = after.find('>').unwrap_or(after.len());
        let open = &after[..open_end];
        let close = after.find("</svg>").unwrap_or(after.len());
        let body = &after[open_end.min(close)..close];
        let sized = attr_positive(open, "width") && attr_positive(open, "height");
        if !(sized && has_drawn_element(body)) {
            empty += 1;
        }
        rest = &after[close.min(after.len())..];
        if rest.len() == after.len() {
            break;
        }
    }
    (n, empty)
}

/// Whether the open tag has ` name="<positive number>…"`.
fn attr_positive(open: &str, name: &str) -> bool {
    let key = format!(" {name}=\"");
    let Some(i) = open.find(&key) else {
        return false;
    };
    let v = &open[i + key.len()..];
    let num: String = v
        .chars()
        .take_while(|c| c.is_ascii_digit() || *c == '.')
        .collect();
    num.parse::<f64>().is_ok_and(|x| x > 0.0)
}

/// Whether an SVG body draws something outside its `<defs>`.
fn has_drawn_element(body: &str) -> bool {
    let mut visible = String::with_capacity(body.len());
    let mut rest = body;
    while let Some(i) = rest.find("<defs") {
        visible.push_str(&rest[..i]);
        match rest[i..].find("</defs>") {
            Some(j) => rest = &rest[i + j + 7..],
            None => {
                rest = "";
            }
        }
    }
    visible.push_str(rest);
    [
        "<path",
        "<line",
        "<polyline",
        "<polygon",
        "<rect",
        "<circle",
        "<ellipse",
        "<text",
    ]
    .iter()
    .any(|t| visible.contains(t))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fake browser: a shell script that counts its starts in `calls` and does what `body`
    /// says.
    fn fake_browser(dir: &Path, body: &str) -> PathBuf {
        use std::os::unix::fs::PermissionsExt;
        let script = dir.join("fake-chromium");
        let calls = dir.join("calls");
        fs::write(
            &script,
            format!(
                "#!/bin/sh\necho x >> '{}'\nn=$(wc -l < '{}')\n{body}\n",
                calls.display(),
                calls.display()
            ),
        )
        .unwrap();
        fs::set_permissions(&script, fs::Permissions::from_mode(0o755)).unwrap();
        script
    }

    fn starts(dir: &Path) -> usize {
        fs::read_to_string(dir.join("calls"))
            .map(|s| s.lines().count())
            .unwrap_or(0)
    }

    #[test]
    fn a_hung_run_is_started_once_more_and_a_failed_one_is_not() {
        let short = Duration::from_millis(1500);
        // Hangs on its first start, answers on the second.
        let dir = TempDir::new().unwrap();
        let fake = fake_browser(
            &dir.0,
            "if [ \"$n\" -eq 1 ]; then exec sleep 30; fi\necho rendered",
        );
        let out = run_chromium_within(&fake, &dir.0, "t", &[], short).unwrap();
        assert_eq!(out.stdout.trim(), "rendered");
        assert_eq!(starts(&dir.0), 2);
        // Hangs every time: one retry, then the time-out is the error.
        let dir = TempDir::new().unwrap();
        let fake = fake_browser(&dir.0, "exec sleep 30");
        let err = run_chromium_within(&fake, &dir.0, "t", &[], short).unwrap_err();
        assert!(err.contains("timed out"), "{err}");
        assert_eq!(starts(&dir.0), 1 + HANG_RETRIES);
        // Fails: no retry, the exit status and the log's tail are the error.
        let dir = TempDir::new().unwrap();
        let fake = fake_browser(&dir.0, "echo broken >&2\nexit 3");
        let err = run_chromium_within(&fake, &dir.0, "t", &[], short).unwrap_err();
        assert!(err.contains("failed") && err.contains("broken"), "{err}");
        assert_eq!(starts(&dir.0), 1);
    }

    #[test]
    fn debug_text_finds_rust_debug_output_and_not_plain_words() {
        let hits =
            debug_text("measured 15.3 (Some((0.0, 42.5))) → zone D; tol of PzOptions::default()");
        assert_eq!(hits.len(), 2, "{hits:?}");
        assert!(hits[0].contains("Some(("));
        assert!(hits[1].contains("PzOptions::default"));
        assert_eq!(debug_text("value: None\n").len(), 1);
        for fine in [
            "none of the levels",
            "Nonexistent",
            "NoneSuch",
            "a: b, c ratio 1:2",
        ] {
            assert!(debug_text(fine).is_empty(), "{fine}");
        }
    }

    #[test]
    fn svg_counting() {
        let dom = r#"<html><body>
<svg width="100" height="50"><defs><clipPath id="c"><rect/></clipPath></defs><path d="M0 0L1 1"/></svg>
<svg width="100" height="50"><defs><rect/></defs></svg>
<svg width="0" height="50"><text>x</text></svg>
<svgfoo></svgfoo>
<svg height="10" width="10"><g><text>t</text></g></svg>
</body></html>"#;
        assert_eq!(count_svgs(dom), (4, 2));
    }

    #[test]
    fn console_lines() {
        let log = "\
[1:2:1121/1.0:INFO:CONSOLE:1] \"Uncaught ReferenceError: foo\", source: file:///tmp/r.html (1)
[1:2:1121/1.0:INFO:CONSOLE(0)] \"Failed to load resource: net::ERR_FILE_NOT_FOUND\", source: file:///tmp/x.png (0)
[1:2:1121/1.0:ERROR:dbus/bus.cc:405] Failed to connect to the bus
[1:2:1121/1.0:WARNING:sandbox/policy/linux/sandbox_linux.cc:405] InitializeSandbox()
[1:2:1121/1.0:ERROR:net/x.cc:1] could not read /tmp/r.html
";
        let e = console_errors_in(log, "r.html");
        assert_eq!(e.len(), 3, "{e:?}");
    }

    #[test]
    fn external_references() {
        let ok = r##"<svg xmlns="http://www.w3.org/2000/svg"><g clip-path="url(#c1)"><rect fill="url(#g)"/></g></svg><a href="#frf">x</a>"##;
        assert!(external_refs(ok).is_empty(), "{:?}", external_refs(ok));
        let bad = r#"<link rel="stylesheet" href="x.css"><img src="a.png"><div style="background:url('b.png')"></div>"#;
        assert_eq!(external_refs(bad).len(), 4, "{:?}", external_refs(bad));
    }

    #[test]
    fn url_encoding() {
        assert_eq!(
            file_url(Path::new("/tmp/a b/r#1.html")),
            "file:///tmp/a%20b/r%231.html"
        );
    }
}
