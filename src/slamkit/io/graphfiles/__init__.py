"""The machinery behind :mod:`slamkit.io.posegraph`: the orderings and noise conventions of
each graph-file family (:mod:`.conventions`), what each tag holds (:mod:`.families`), the
reader (:mod:`.reader`) and the writer (:mod:`.writer`)."""
