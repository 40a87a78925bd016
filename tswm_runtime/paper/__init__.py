"""The paper report (``tswm paper``): the paper's printed data, the four readings, the
lost-motion fit and the Markdown/HTML/JSON report. Imports simulation/, fitting/, reference/."""
