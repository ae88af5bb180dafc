"""What the messages say, in both processes: handshake, batch encodings, action rules, stream credit, zygote control."""
