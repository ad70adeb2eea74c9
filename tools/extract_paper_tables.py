#!/usr/bin/python3
"""Extracts the CSV blocks (filecontents*) of the paper's LaTeX source into data/published/.

Usage: tools/extract_paper_tables.py [PAPER.tex] [OUT_DIR]
The paper embeds its result tables and the SimDyn coefficient table as CSV; they are copied
verbatim with a header comment naming the source table, so `spml compare` and the tests
compare against exactly what was published."""
import os
import re
import sys

here = os.path.dirname(os.path.abspath(__file__))
paper = sys.argv[1] if len(sys.argv) > 1 else os.path.join(here, "..", "..", "shared", "paper", "semiparametric-model-learning.tex")
out = sys.argv[2] if len(sys.argv) > 2 else os.path.join(here, "..", "data", "published")
text = open(paper, encoding="utf-8").read()
blocks = re.findall(r"\\caption \{\\label\{(tab:[^}]*)\}(.*?)\}\s*\n.*?\\begin\{filecontents\*\}\{\./csvs/([^}]+)\}\n(.*?)\\end\{filecontents\*\}", text, re.S)
os.makedirs(out, exist_ok=True)
for label, caption, name, body in blocks:
    caption = re.sub(r"\\[a-z]+\{\}", "", caption).strip()
    with open(os.path.join(out, name), "w") as f:
        f.write(body)
    print(f"{name}: {label}, {len(body.strip().splitlines()) - 1} rows")
print(f"{len(blocks)} tables written to {out}")
