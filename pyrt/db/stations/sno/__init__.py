"""The full-scale SNO station: five ropes in the 600.5 cm vessel (Figure 2 of 000)."""
