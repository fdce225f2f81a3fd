"""Analysis: statistics and their intervals, requirements and their verdicts, the --until stopping
rule, the printed summaries and the figures of an ensemble."""
