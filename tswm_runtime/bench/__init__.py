"""The benchmark (``tswm bench``): tswm against scipy and CVODE at equal error, its cases, the
peers as a careful user writes them, and the report. Imports simulation/, sweeps/, reference/."""
