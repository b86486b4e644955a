#!/usr/bin/env python3
"""Runs the commands the README shows and compares their output with it.

So the README cannot drift: ctest runs this against the phos binary it built
(tests/CMakeLists.txt, test "readme"), and `--update` rewrites the README's
outputs from real runs when a change alters them on purpose.

The README's convention (pure Markdown, nothing else to learn):

- A console block is a code block (indented by 4 spaces, or fenced) whose
  first line starts with "$ ". Every "$ " line is a command, run with bash
  from a scratch folder that holds `fixtures` (a link to the repository's)
  and `build/bin/phos` (a link to the binary under test), so the commands
  read exactly as a user types them from the repository's root. Outputs go
  to that scratch folder, never into the repository. A line ending in "\\"
  continues the command on the next line. `$?` is the exit code of the
  command before, as in a shell.
- The lines after a command, up to the next "$ " line or the block's end,
  are its output (stdout and stderr as they interleave). A command with no
  output lines has its output left out on purpose: it only has to exit 0.
- A line ending in "..." is cut: only what comes before the "..." is
  compared. A line that is just "..." stands for any further lines.
- Comparison: text must match, with runs of spaces counted as one space (so
  a table's alignment may follow its numbers). Numbers are compared as
  numbers: integers exactly, others to a relative tolerance (--rtol, default
  1e-3, for the last digits a sanitizer build or another CPU may change).
  Timings are masked (any number before " ms", "(N s)", JSON keys ending in
  "seconds", the time column of `phos render`): they only have to be
  numbers.
- HTML comments just before a block (invisible on GitHub) adjust it:
    <!-- readme-check: skip "TEXT": REASON -->   commands containing TEXT are
        not run (every command of the block without "TEXT"); the reason is
        printed. For commands that never end (a server) or whose output
        depends on the machine's speed.
    <!-- readme-check: slow "TEXT": REASON -->   not run by default (the CI
        budget), run with --all and --update.
    <!-- readme-check: setup: COMMAND -->        run first, output hidden,
        must exit 0 (to make the files a command reads).
    <!-- readme-check: until "TEXT": N lines -->  a command that runs until
        Ctrl-C (a server): its first N lines are compared, then it gets SIGINT.
    <!-- readme-check: args "TEXT": ARGS -->      ARGS are added to commands
        containing TEXT when they run (a free port instead of a fixed one).
    <!-- readme-check: mask /REGEX/ -->          numbers inside the match
        (group 1 if it has one) are masked in this block.
    <!-- readme-check: rtol X -->                this block's tolerance.

Exit code 0 when every command that ran matched, 1 otherwise (each
difference is printed), 2 for a usage error. Python 3 standard library only.
"""

import argparse
import difflib
import os
import re
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time

NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
# A number not glued to an identifier before it ("r_1", "L_8", "x86" stay text).
NUM_TOKEN = re.compile(r"(?<![\w.])" + NUM + r"(?![\w.])|(?<![\w.])" + NUM + r"(?=[A-Za-z_%])")
INTEGER = re.compile(r"[-+]?\d+$")

DEFAULT_MASKS = [
    r"(" + NUM + r") ms\b",                      # "1.41 ms", "solved in 1.54 ms"
    r"\((" + NUM + r") s\)",                     # "phos fit session: ... (0.6576 s)"
    r'"\w*seconds":(' + NUM + r")",              # JSON "seconds", "render_seconds", ...
    r"t = +" + NUM + r" s +(" + NUM + r") s",    # phos render: "t =   20 s    0.014 s  out/..."
    r"\bin (" + NUM + r") s\b",                  # "fitted in 11.04 s"
]

DIRECTIVE = re.compile(r"<!--\s*readme-check:\s*(.*?)\s*-->", re.S)


class Command:
    def __init__(self, text, line_no):
        self.text = text          # as written (continuation lines joined with "\\\n")
        self.line_no = line_no    # 1-based line of the "$ " line in the README
        self.output = []          # expected output lines (block indentation removed)
        self.first_out = None     # README index (0-based) of the first output line
        self.end = None           # README index just past the output


class Block:
    def __init__(self):
        self.commands = []
        self.indent = ""
        self.skips = []     # (text or None, reason)
        self.slows = []
        self.setup = []
        self.untils = []    # (text, lines): a command that runs until Ctrl-C
        self.args = []      # (text, extra arguments)
        self.masks = []
        self.rtol = None


def parse(lines):
    """Finds the console blocks of a Markdown file (a list of lines without newlines)."""
    blocks = []
    pending = []  # directives seen since the last block
    i = 0
    in_fence = None
    n = len(lines)
    while i < n:
        line = lines[i]
        # Directives (possibly several on a line, or spanning lines).
        if "<!--" in line and "readme-check" in line:
            j = i
            text = line
            while "-->" not in text and j + 1 < n:
                j += 1
                text += "\n" + lines[j]
            pending.extend(m.group(1) for m in DIRECTIVE.finditer(text))
            i = j + 1
            continue
        fence = re.match(r"^(\s*)(```+|~~~+)", line)
        if fence:
            # A fenced block: its body up to the closing fence.
            indent, marker = fence.group(1), fence.group(2)
            body_start = i + 1
            k = body_start
            while k < n and not lines[k].strip().startswith(marker):
                k += 1
            body = [(idx, lines[idx][len(indent):] if lines[idx].startswith(indent) else lines[idx].lstrip())
                    for idx in range(body_start, k)]
            if body and body[0][1].startswith("$ "):
                blocks.append(make_block(body, indent, pending))
            pending = []
            i = k + 1
            continue
        if line.startswith("    ") and (i == 0 or lines[i - 1].strip() == "" or lines[i - 1].startswith("<!--")
                                         or lines[i - 1].rstrip().endswith("-->")):
            k = i
            body = []
            while k < n:
                if lines[k].startswith("    "):
                    body.append((k, lines[k][4:]))
                    k += 1
                elif lines[k].strip() == "":
                    # A blank line belongs to the block if the block goes on after it.
                    m = k
                    while m < n and lines[m].strip() == "":
                        m += 1
                    if m < n and lines[m].startswith("    "):
                        body.extend((idx, "") for idx in range(k, m))
                        k = m
                    else:
                        break
                else:
                    break
            if body and body[0][1].startswith("$ "):
                blocks.append(make_block(body, "    ", pending))
            pending = []
            i = k
            continue
        if line.strip() and not line.startswith("<!--"):
            # Prose between a directive and its block: the directive still waits for the next block.
            pass
        i += 1
    return blocks


def make_block(body, indent, directives):
    block = Block()
    block.indent = indent
    for d in directives:
        apply_directive(block, d)
    k = 0
    current = None
    while k < len(body):
        idx, text = body[k]
        if text.startswith("$ "):
            cmd = text[2:]
            start = idx
            while cmd.endswith("\\") and k + 1 < len(body):
                k += 1
                cmd += "\n" + body[k][1]
            current = Command(cmd, start + 1)
            current.first_out = body[k][0] + 1
            current.end = current.first_out
            block.commands.append(current)
        elif current is not None:
            current.output.append(text)
            current.end = idx + 1
        k += 1
    for c in block.commands:
        # Trailing blank lines are not output.
        while c.output and c.output[-1] == "":
            c.output.pop()
            c.end -= 1
    return block


def apply_directive(block, d):
    m = re.match(r'(skip|slow)\s*(?:"([^"]*)")?\s*:?\s*(.*)$', d, re.S)
    if m:
        (block.skips if m.group(1) == "skip" else block.slows).append((m.group(2), m.group(3).strip()))
        return
    m = re.match(r'until\s*"([^"]*)"\s*:\s*(\d+)\s*lines?\s*$', d)
    if m:
        block.untils.append((m.group(1), int(m.group(2))))
        return
    m = re.match(r'args\s*"([^"]*)"\s*:\s*(.*)$', d, re.S)
    if m:
        block.args.append((m.group(1), m.group(2).strip()))
        return
    m = re.match(r"setup\s*:\s*(.*)$", d, re.S)
    if m:
        block.setup.append(m.group(1).strip())
        return
    m = re.match(r"mask\s*/(.*)/$", d, re.S)
    if m:
        block.masks.append(m.group(1))
        return
    m = re.match(r"rtol\s+(" + NUM + r")$", d)
    if m:
        block.rtol = float(m.group(1))
        return
    raise SystemExit("readme_check: unknown directive <!-- readme-check: %s -->" % d)


def matching(rules, command):
    for text, reason in rules:
        if text is None or text in command.text:
            return reason or "(no reason given)"
    return None


# ---- comparison --------------------------------------------------------------

def tokens(line, masks):
    """Splits a line into ("text", s) and ("num", s, masked) tokens."""
    spans = []
    for mask in masks:
        for m in re.finditer(mask, line):
            spans.append(m.span(1) if m.groups() else m.span())
    out = []
    pos = 0
    for m in NUM_TOKEN.finditer(line):
        if m.start() > pos:
            out.append(("text", line[pos:m.start()]))
        masked = any(a <= m.start() and m.end() <= b for a, b in spans)
        out.append(("num", m.group(), masked))
        pos = m.end()
    if pos < len(line):
        out.append(("text", line[pos:]))
    return out


def squeeze(s):
    return re.sub(r"\s+", " ", s)


def numbers_match(e, a, rtol):
    if INTEGER.match(e) and INTEGER.match(a):
        return int(e) == int(a)
    x, y = float(e), float(a)
    return abs(x - y) <= rtol * max(abs(x), abs(y)) or x == y


def line_matches(expected, actual, masks, rtol):
    """None if they match, else a short reason."""
    cut = expected.rstrip().endswith("...")
    if cut:
        expected = expected.rstrip()[:-3]
    e_tokens = tokens(expected.strip(), masks)
    a_tokens = tokens(actual.strip(), masks)
    if cut:
        a_tokens = a_tokens[:len(e_tokens)]
    if len(e_tokens) != len(a_tokens) and not cut:
        return "differs"
    for k, (e, a) in enumerate(zip(e_tokens, a_tokens)):
        last = cut and k == len(e_tokens) - 1
        if e[0] == "text" or a[0] == "text":
            es, as_ = squeeze(e[1]), squeeze(a[1])
            if e[0] != a[0] and not last:
                return "differs"
            if last:
                if not squeeze(a[1]).startswith(es) and not (e[0] == "num" and a[0] == "num"):
                    return "differs"
            elif es != as_:
                return "differs"
            continue
        if e[2] or a[2]:
            continue  # a timing
        if last and a[1].startswith(e[1]):
            continue  # the cut fell inside this number
        if not numbers_match(e[1], a[1], rtol):
            return "%s instead of %s" % (a[1], e[1])
    if cut and len(a_tokens) < len(e_tokens):
        return "shorter than shown"
    return None


def shape(line):
    """A line with its numbers blanked: lines of one shape can be compared number by number."""
    return squeeze(NUM_TOKEN.sub("#", line.rstrip()[:-3] if line.rstrip().endswith("...") else line)).strip()


def compare(expected, actual, masks, rtol):
    """A list of difference lines (empty if the output matches)."""
    diffs = []
    more = bool(expected) and expected[-1].strip() == "..."
    if more:
        expected = expected[:-1]
    if len(actual) != len(expected) and not (more and len(actual) > len(expected)):
        # Lines missing or added: a diff says where.
        diffs.append("  %d line(s) shown, %d printed (- README, + actual):" % (len(expected), len(actual)))
        matcher = difflib.SequenceMatcher(None, [shape(e) for e in expected], [shape(a) for a in actual],
                                          autojunk=False)
        for tag, i1, i2, j1, j2 in matcher.get_opcodes():
            if tag != "equal":
                diffs.extend("    - " + e for e in expected[i1:i2])
                diffs.extend("    + " + a for a in actual[j1:j2])
        return diffs
    for k, e in enumerate(expected):
        if k >= len(actual):
            diffs.append("  missing line %d: %s" % (k + 1, e))
            continue
        why = line_matches(e, actual[k], masks, rtol)
        if why:
            diffs.append("  line %d %s\n    README: %s\n    actual: %s" % (k + 1, why, e, actual[k]))
    if len(actual) > len(expected) and not more:
        for k in range(len(expected), len(actual)):
            diffs.append("  extra line %d: %s" % (k + 1, actual[k]))
    return diffs


# ---- running -----------------------------------------------------------------

def prepare_workdir(work, source_dir, phos):
    os.makedirs(os.path.join(work, "build", "bin"), exist_ok=True)
    link = os.path.join(work, "build", "bin", "phos")
    if os.path.lexists(link):
        os.remove(link)
    os.symlink(os.path.abspath(phos), link)
    fixtures = os.path.join(work, "fixtures")
    if not os.path.lexists(fixtures):
        os.symlink(os.path.join(os.path.abspath(source_dir), "fixtures"), fixtures)


def run_until(command, work, lines, timeout):
    """Runs a command that goes on until Ctrl-C (a server): waits for its
    first `lines` lines of output, then sends SIGINT, as a user would."""
    env = dict(os.environ, LC_ALL="C", TZ="UTC", COLUMNS="200")
    start = time.monotonic()
    p = subprocess.Popen(["bash", "-c", "exec " + command], cwd=work, env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT)
    out = b""
    deadline = start + timeout
    try:
        while out.count(b"\n") < lines and time.monotonic() < deadline:
            ready, _, _ = select.select([p.stdout], [], [], max(0.0, deadline - time.monotonic()))
            if not ready:
                break
            chunk = os.read(p.stdout.fileno(), 65536)
            if not chunk:
                break  # it ended by itself
            out += chunk
    finally:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        p.stdout.close()
    text = out.decode("utf-8", "replace")
    kept = text.split("\n")[:lines]
    return "\n".join(kept) + "\n", 0 if out.count(b"\n") >= lines else 1, time.monotonic() - start


def run(command, work, status, timeout):
    """Runs one command with bash in `work`; `$?` starts as `status`."""
    env = dict(os.environ, LC_ALL="C", TZ="UTC", COLUMNS="200")
    script = "(exit %d)\n%s" % (status, command)
    start = time.monotonic()
    try:
        p = subprocess.run(["bash", "-c", script], cwd=work, env=env, stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, timeout=timeout)
        out, rc = p.stdout.decode("utf-8", "replace"), p.returncode
    except subprocess.TimeoutExpired as e:
        out = (e.stdout or b"").decode("utf-8", "replace") + "\n(timed out after %d s)" % timeout
        rc = 124
    return out, rc, time.monotonic() - start


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--phos", default=None, help="the phos binary (default: SOURCE/build/bin/phos)")
    ap.add_argument("--source-dir", default=os.path.dirname(here), help="the repository (fixtures/, README.md)")
    ap.add_argument("--readme", default=None, help="the Markdown file (default: SOURCE/README.md)")
    ap.add_argument("--work", default=None, help="scratch folder (default: a temporary one, removed after)")
    ap.add_argument("--keep", action="store_true", help="keep the scratch folder")
    ap.add_argument("--all", action="store_true", help="also run the commands marked slow")
    ap.add_argument("--update", action="store_true",
                    help="rewrite the README's outputs from the actual ones (implies --all; run with the Release binary)")
    ap.add_argument("--only", default=None, help="run only the commands containing this text (and the setups)")
    ap.add_argument("--rtol", type=float, default=1e-3, help="relative tolerance of non-integer numbers (default 1e-3)")
    ap.add_argument("--timeout", type=int, default=300, help="seconds allowed per command (default 300)")
    ap.add_argument("--self-test", action="store_true", help="check the parser and the comparison on built-in cases")
    args = ap.parse_args()
    if args.self_test:
        return self_test()

    source = os.path.abspath(args.source_dir)
    readme = args.readme or os.path.join(source, "README.md")
    phos = args.phos or os.path.join(source, "build", "bin", "phos")
    if not os.access(phos, os.X_OK):
        print("readme_check: %s: no phos binary there (build it, or give --phos)" % phos, file=sys.stderr)
        return 2
    with open(readme, encoding="utf-8") as f:
        text = f.read()
    lines = text.split("\n")
    blocks = parse(lines)
    if not blocks:
        print("readme_check: %s: no console blocks (code blocks starting with '$ ')" % readme, file=sys.stderr)
        return 2

    work = args.work or tempfile.mkdtemp(prefix="phos-readme-")
    if args.work and os.path.isdir(work):
        if any(os.path.exists(os.path.join(work, name)) for name in (".git", "README.md", "CMakeLists.txt")):
            print("readme_check: --work %s looks like a source tree; give a scratch folder" % work, file=sys.stderr)
            return 2
        shutil.rmtree(work)
    os.makedirs(work, exist_ok=True)
    prepare_workdir(work, source, phos)
    run_all = args.all or args.update

    failed = ran = skipped = 0
    replacements = []  # (start, end, new lines) in README line indices
    total_start = time.monotonic()
    rel = os.path.relpath(readme, source)
    for block in blocks:
        masks = DEFAULT_MASKS + block.masks
        rtol = block.rtol if block.rtol is not None else args.rtol
        for setup in block.setup:
            out, rc, _ = run(setup, work, 0, args.timeout)
            if rc != 0:
                failed += 1
                print("FAIL %s: setup `%s` exited %d:\n%s" % (rel, setup, rc, out.rstrip()))
        status = 0
        for c in block.commands:
            where = "%s:%d" % (rel, c.line_no)
            shown = c.text.replace("\\\n", " ").split("\n")[0]
            shown = re.sub(r"\s+", " ", shown)
            reason = matching(block.skips, c)
            if reason is None and not run_all:
                reason = matching(block.slows, c)
                if reason is not None:
                    reason = "slow: " + reason + " (runs with --all)"
            if reason is None and args.only and args.only not in c.text:
                reason = "not selected by --only"
            if reason is not None:
                skipped += 1
                print("SKIP %s  $ %s\n     %s" % (where, shown, reason))
                continue
            command = c.text
            for text, extra in block.args:
                if text in command:
                    command += " " + extra
            until = next((n for text, n in block.untils if text in c.text), None)
            if until is not None:
                out, rc, seconds = run_until(command, work, until, args.timeout)
            else:
                out, rc, seconds = run(command, work, status, args.timeout)
            status = rc
            ran += 1
            actual = out.split("\n")
            if actual and actual[-1] == "":
                actual.pop()
            actual = [a.rstrip() for a in actual]
            if not c.output:
                diffs = [] if rc == 0 else ["  exit code %d (no output shown, so 0 expected):" % rc] + \
                    ["    " + a for a in actual[:20]]
            else:
                diffs = compare(c.output, actual, masks, rtol)
            if diffs:
                failed += 1
                print("FAIL %s  $ %s  (%.2f s)" % (where, shown, seconds))
                print("\n".join(diffs))
            else:
                print("ok   %s  $ %s  (%.2f s)" % (where, shown, seconds))
            if args.update and c.output and diffs:
                replacements.append((c.first_out, c.end, updated_lines(c.output, actual, block.indent, masks, rtol)))
    total = time.monotonic() - total_start
    print("readme_check: %d command(s) run, %d skipped, %d failed, %.1f s (%s)" % (ran, skipped, failed, total, phos))

    if args.update:
        for start, end, new in sorted(replacements, reverse=True):
            lines[start:end] = new
        new_text = "\n".join(lines)
        if new_text != text:
            with open(readme + ".tmp", "w", encoding="utf-8") as f:
                f.write(new_text)
            os.replace(readme + ".tmp", readme)
            print("readme_check: rewrote the outputs in %s" % readme)
        else:
            print("readme_check: %s already shows these outputs" % readme)
    if not args.keep and not args.work:
        shutil.rmtree(work, ignore_errors=True)
    elif args.keep:
        print("readme_check: scratch folder kept: %s" % work)
    if args.update:
        return 0
    return 1 if failed else 0


def updated_lines(expected, actual, indent, masks, rtol):
    """The output lines to write back for a command whose output differs.

    Lines that still match (timings aside) stay as the README has them, so an
    update changes only what drifted; the others become the actual lines,
    cut where the README cut them."""
    more = bool(expected) and expected[-1].strip() == "..."
    shown = expected[:-1] if more else expected
    printed = actual[:len(shown)] if more else list(actual)
    # Pair the README's lines with the printed ones by their shape (numbers
    # blanked), so an added or removed line leaves the others as they were.
    pairs = {}
    matcher = difflib.SequenceMatcher(None, [shape(e) for e in shown], [shape(a) for a in printed], autojunk=False)
    for tag, i1, i2, j1, j2 in matcher.get_opcodes():
        if tag in ("equal", "replace") and i2 - i1 == j2 - j1:
            for d in range(i2 - i1):
                pairs[j1 + d] = i1 + d
    new = []
    for k, a in enumerate(printed):
        e = shown[pairs[k]] if k in pairs else None
        if e is not None and line_matches(e, a, masks, rtol) is None:
            new.append(e)
            continue
        # A line the README cut with "..." is cut again at the same length.
        if e is not None and e.rstrip().endswith("...") and e.strip() != "...":
            length = len(e.rstrip()) - 3
            if len(a) > length:
                a = a[:length] + "..."
        new.append(a)
    if more:
        new.append("...")
    return [(indent + a) if a else "" for a in new]


def self_test():
    """The checker's own test: what must match does, and a drift is caught."""
    failures = []

    def expect(name, ok):
        print("%s %s" % ("ok  " if ok else "FAIL", name))
        if not ok:
            failures.append(name)

    m, r = DEFAULT_MASKS, 1e-3
    same = lambda e, a: compare(e, a, m, r) == []
    expect("equal output matches", same(["  decay            42 frames"], ["  decay            42 frames"]))
    expect("a frame count that drifted is caught (57 against 55)",
           not same(["  excitation       57 frames"], ["  excitation       55 frames"]))
    expect("a missing line is caught",
           not same(["a", "  joint refinement (written): kr = 0.015 /s", "b"], ["a", "b"]))
    expect("an extra line is caught", not same(["a"], ["a", "b"]))
    expect("timings are masked",
           same(["rss 77.9949, 1.41 ms", "fit session: d -> m.json (0.6576 s)", '{"seconds":0.0011,"x":1}',
                 "  t =       20 s    0.014 s  out/frame-0000.png", "fitted in 11.04 s -> x"],
                ["rss 77.9949, 8.35 ms", "fit session: d -> m.json (7.9 s)", '{"seconds":0.09,"x":1}',
                 "  t =       20 s    0.151 s  out/frame-0000.png", "fitted in 15.42 s -> x"]))
    expect("a time that is not a timing is compared",
           not same(["  t =       20 s    0.014 s  out/frame-0000.png"], ["  t =       40 s    0.014 s  out/frame-0000.png"]))
    expect("numbers within the tolerance match", same(["rate 1.20177 /s"], ["rate 1.201771 /s"]))
    expect("numbers beyond it do not", not same(["rss 77.9949"], ["rss 78.1"]))
    expect("integers are exact", not same(["37132 phosphor texels"], ["37133 phosphor texels"]))
    expect("runs of spaces count as one", same(["a   nc  1.5"], ["a nc    1.5"]))
    expect("identifiers keep their digits as text", not same(["r_1,L_1"], ["r_1,L_2"]))
    expect("a cut line compares its prefix", same(['{"t":[0,5],"L":[[0,0.0074,...'], ['{"t":[0,5],"L":[[0,0.0074,0.07585]]}']))
    expect("a cut line still catches a drift before the cut",
           not same(['{"t":[0,5],"L":[[0,0.0075,...'], ['{"t":[0,5],"L":[[0,0.0074,0.07585]]}']))
    expect("'...' alone stands for further lines", same(["a", "..."], ["a", "b", "c"]))
    expect("text differences are caught", not same(["phos: --dt: euler"], ["phos: --dt: rk4"]))

    readme = ["intro", "", "<!-- readme-check: skip \"editor\": a server -->", "",
              "    $ build/bin/phos simulate --material m.json \\", "        --dt 5", "    t,r_1", "    0,0",
              "    $ echo $?", "    0", "", "Prose.", "", "    make demo", "", "```console", "$ build/bin/phos editor", "listening",
              "```"]
    blocks = parse(readme)
    expect("console blocks are found, plain code blocks are not", len(blocks) == 2)
    if len(blocks) == 2:
        c = blocks[0].commands
        expect("a continued command is one command with its output",
               len(c) == 2 and c[0].text.endswith("--dt 5") and c[0].output == ["t,r_1", "0,0"] and c[1].output == ["0"])
        expect("a directive applies to the next block", blocks[0].skips == [("editor", "a server")])
        expect("fenced blocks are read", blocks[1].commands[0].output == ["listening"])
    served = parse(["<!-- readme-check: until \"phos editor\": 1 line -->", "<!-- readme-check: args \"phos editor\": --port 0 -->",
                    "", "    $ build/bin/phos editor", "    phos editor: on http://127.0.0.1:8377/"])
    expect("until and args directives are read",
           len(served) == 1 and served[0].untils == [("phos editor", 1)] and served[0].args == [("phos editor", "--port 0")])
    server = "%s -c \"import sys, time; print('first'); print('second'); sys.stdout.flush(); time.sleep(30)\"" % (
        sys.executable)
    start = time.monotonic()
    out, rc, _ = run_until(server, tempfile.gettempdir(), 1, 20)
    expect("a server's first lines are read and Ctrl-C stops it",
           out == "first\n" and rc == 0 and time.monotonic() - start < 5)
    new = updated_lines(["phos fit session: (0.6 s)", "  nc = 1", "  report: r.html"],
                        ["phos fit session: (0.9 s)", "  nc = 1", "  joint refinement (written)", "  report: r.html"],
                        "    ", m, r)
    expect("--update keeps matching lines (timings too) and adds the new one",
           new == ["    phos fit session: (0.6 s)", "      nc = 1", "      joint refinement (written)", "      report: r.html"])
    print("readme_check self-test: %d failed" % len(failures))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
