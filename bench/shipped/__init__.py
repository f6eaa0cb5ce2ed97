"""The generators of the files shipped with the case sets: ``ecodrive cases`` (``cases_command``:
writes and checks the fixed cases, the families, the shipped bounds and clairvoyant drives) and
``drives`` (clairvoyant's planning of whole case sets). They run the methods and the DP, so they
sit above the methods and the harness; the run reads what they wrote (``bench.cases``)."""
