#!/usr/bin/env bash
# Checks an ambid HTML report in headless Chromium (the same checks as
# ambid::report::browser_check):
#   - a full-page screenshot is written and is not trivial,
#   - every <svg> in the rendered DOM draws something and has a non-zero width and height,
#   - Chromium logs no console message for the page (a report has no script, so any console
#     line is an error),
#   - the rendered DOM references no external resource (src/href/url() outside '#fragment',
#     <script>, <link>, @import, ...).
#
# Usage: scripts/check-report.sh report.html [screenshot.png]
# Environment: CHROMIUM (default /usr/bin/chromium).
# Exit status: 0 fine (or Chromium not installed: prints "skipped: ..."), 1 problems found,
# 2 usage or Chromium failure.
set -euo pipefail

if [ $# -lt 1 ] || [ $# -gt 2 ]; then
    echo "usage: $0 report.html [screenshot.png]" >&2
    exit 2
fi
html=$1
chromium=${CHROMIUM:-/usr/bin/chromium}
if [ ! -f "$html" ]; then
    echo "error: $html: no such file" >&2
    exit 2
fi
if [ ! -x "$chromium" ]; then
    echo "skipped: $chromium not installed (Debian: apt-get install -y chromium)"
    exit 0
fi

abs=$(cd "$(dirname "$html")" && pwd)/$(basename "$html")
url="file://$(printf '%s' "$abs" | perl -pe 's{([^A-Za-z0-9/._~-])}{sprintf("%%%02X", ord($1))}ge')"
tmp=$(mktemp -d "${TMPDIR:-/tmp}/check-report.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
shot=${2:-$tmp/screenshot.png}

run_chromium() { # tag, extra args...
    local tag=$1
    shift
    timeout 120 "$chromium" --headless --no-sandbox --disable-gpu --disable-quic --no-first-run \
        --disable-background-networking --disable-component-update --disable-sync \
        --user-data-dir="$tmp/profile-$tag" --enable-logging=stderr --v=0 "$@" "$url" \
        >"$tmp/$tag.out" 2>"$tmp/$tag.err" || {
        echo "error: chromium ($tag) failed:" >&2
        tail -5 "$tmp/$tag.err" >&2
        exit 2
    }
}

run_chromium shot --screenshot="$shot" --window-size=1280,8000 --hide-scrollbars
run_chromium dom --dump-dom

problems=0
shot_bytes=$(stat -c %s "$shot" 2>/dev/null || echo 0)
# A blank white 1280x8000 page is about 46 kB as PNG; a report with only its header ~65 kB.
if [ "$shot_bytes" -le 55000 ]; then
    echo "problem: screenshot missing or trivial ($shot_bytes bytes)"
    problems=$((problems + 1))
fi

# SVG elements: count, and those without a drawn element (outside <defs>) or without a
# positive width/height attribute.
read -r svgs empty < <(perl -0777 -ne '
    my $dom = lc $_; my ($n, $e) = (0, 0);
    while ($dom =~ m{<svg([\s>][^>]*)>(.*?)</svg>}gs) {
        my ($open, $body) = ($1, $2); $n++;
        $body =~ s{<defs.*?</defs>}{}gs;
        my $sized = ($open =~ /\swidth="([0-9.]+)/ && $1 > 0) && ($open =~ /\sheight="([0-9.]+)/ && $1 > 0);
        my $drawn = $body =~ /<(path|line|polyline|polygon|rect|circle|ellipse|text)[\s>\/]/;
        $e++ unless $sized && $drawn;
    }
    print "$n $e\n";' "$tmp/dom.out")
if [ "$svgs" -eq 0 ]; then
    echo "problem: no <svg> in the rendered page"
    problems=$((problems + 1))
fi
if [ "$empty" -gt 0 ]; then
    echo "problem: $empty of $svgs <svg> elements are empty"
    problems=$((problems + 1))
fi

# Console messages and failed loads (both runs).
console=$(cat "$tmp/shot.err" "$tmp/dom.err" |
    grep -E ':CONSOLE|Failed to load resource|Not allowed to load local resource|Refused to|net::ERR_' |
    sed -E 's/^\[[^]]*\] ?//' | sort -u || true)
if [ -n "$console" ]; then
    echo "problem: console messages:"
    printf '%s\n' "$console" | sed 's/^/  /'
    problems=$((problems + 1))
fi

# External resources in the rendered DOM.
external=$(perl -0777 -ne '
    my $dom = lc $_;
    while ($dom =~ /(<script|<link|<iframe|<object|<embed|\@import)/g) { print "  $1\n" }
    while ($dom =~ /(\s(?:src|href|xlink:href)=|url\()\s*["\x27]?([^"\x27\s)>]*)/g) {
        print "  $1$2\n" unless substr($2, 0, 1) eq "#";
    }' "$tmp/dom.out")
if [ -n "$external" ]; then
    echo "problem: external resources:"
    echo "$external"
    problems=$((problems + 1))
fi

echo "svgs: $svgs, empty svgs: $empty, screenshot: $shot_bytes bytes, dom: $(stat -c %s "$tmp/dom.out") bytes"
if [ "$problems" -gt 0 ]; then
    echo "FAILED: $problems problem(s) in $html"
    exit 1
fi
echo "ok: $html renders cleanly"
