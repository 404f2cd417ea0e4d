"""What a person looks at: the acceptance metrics with their bounds, the plots, the HTML
report, and one run written to its folder (traces, metrics, plots, replay, report)."""
