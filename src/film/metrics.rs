//! Image error metrics (RMSE, PSNR, FLIP, SSIM). Filled in by the compare work.
