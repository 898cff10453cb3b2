"""Evaluation: metrics (PSNR, SSIM, LPIPS), the pairs protocol, the synthetic shadow benchmark."""
