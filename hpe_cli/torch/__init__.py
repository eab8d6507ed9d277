"""Optional PyTorch kernels, Dataset and torchvision v2 transforms (extra ``hpe-cli[torch]``)."""
