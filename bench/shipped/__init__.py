"""The generators and checkers of the files shipped with the case sets: ``ecodrive cases``
(``cases_command``), the shipped bounds' (``dp_bounds``: the DP over every fixed case), the
clairvoyant drives' (``drives``: clairvoyant's planning of whole case sets) and the real case
set's (``real_cases``: the routes through the networks and the cases). They run the methods and
the DP, so they sit above the methods and the harness; the run reads what they wrote, through the
readers in ``bench.cases``. The generated families' draws stay beside their readers
(``bench.cases.heldout``, ``train_family``, ``case``), which check a file against them."""
