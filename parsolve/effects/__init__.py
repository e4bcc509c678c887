"""Effects: each contributes operators, forces or relations, and nothing else."""
