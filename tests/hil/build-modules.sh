#!/usr/bin/env bash
# Builds the simulated-device kernel modules Debian's kernel lacks (gpio-sim, irq_sim, vimc).
#
#   tests/hil/build-modules.sh KERNEL_VERSION OUT_DIR
#
# Debian 12's kernel is built without gpio-sim, its irq_sim helper and the vimc virtual camera.
# They build out of tree from linux-source-6.1 against linux-headers-KERNEL_VERSION (which must
# match the kernel image exactly). The .ko files land in OUT_DIR; a second run with the same
# inputs reuses them. Exits 77 when the kernel headers or sources are not installed.
set -euo pipefail

kernel_version=$1
out_dir=$2
headers=/lib/modules/$kernel_version/build
source_tarball=$(ls /usr/src/linux-source-6.1.tar.xz 2>/dev/null || true)

if [ ! -d "$headers" ]; then
    echo "build-modules: no kernel headers at $headers (apt-get install linux-headers-$kernel_version)"
    exit 77
fi
if [ -z "$source_tarball" ]; then
    echo "build-modules: no /usr/src/linux-source-6.1.tar.xz (apt-get install linux-source-6.1)"
    exit 77
fi

stamp="$kernel_version $(stat -c %Y "$source_tarball") $(sha256sum "$0" | cut -c1-16)"
if [ -f "$out_dir/stamp" ] && [ "$(cat "$out_dir/stamp")" = "$stamp" ]; then
    exit 0
fi

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
src=linux-source-6.1
tar -xJf "$source_tarball" -C "$work" \
    $src/kernel/irq/irq_sim.c $src/drivers/gpio/gpio-sim.c $src/drivers/gpio/gpiolib.h \
    $src/drivers/media/test-drivers/vimc

# irq_sim is normally built into the kernel. As a module it needs a licence, and 6.1 does not
# export irq_to_desc(): generic_handle_irq() does the same for an irq number.
mkdir -p "$work/irq_sim"
sed -e 's/handle_simple_irq(irq_to_desc(irqnum));/generic_handle_irq(irqnum);/' \
    "$work/$src/kernel/irq/irq_sim.c" > "$work/irq_sim/irq_sim.c"
grep -q 'generic_handle_irq(irqnum)' "$work/irq_sim/irq_sim.c"
cat >> "$work/irq_sim/irq_sim.c" <<'EOF'

MODULE_LICENSE("GPL");
MODULE_DESCRIPTION("Interrupt simulator, built out of tree for edgetrack's hardware tests");
EOF
echo 'obj-m := irq_sim.o' > "$work/irq_sim/Kbuild"

mkdir -p "$work/gpio_sim"
cp "$work/$src/drivers/gpio/gpio-sim.c" "$work/$src/drivers/gpio/gpiolib.h" "$work/gpio_sim/"
echo 'obj-m := gpio-sim.o' > "$work/gpio_sim/Kbuild"

mkdir -p "$work/vimc"
cp "$work/$src/drivers/media/test-drivers/vimc/"*.[ch] "$work/vimc/"
# vimc registers one platform device, so one camera. The board has two: register two devices
# (vimc.0 and vimc.1, each its own media device and libcamera camera), either of which can be
# unbound through sysfs to take that camera away.
core="$work/vimc/vimc-core.c"
grep -q '"platform:%s", VIMC_PDEV_NAME);' "$core"
sed -i 's/"platform:%s", VIMC_PDEV_NAME);/"platform:%s", dev_name(\&pdev->dev));/' "$core"
sed -i '/^static struct platform_device vimc_pdev = {/,$d' "$core"
cat >> "$core" <<'EOF_VIMC'
static struct platform_device vimc_pdevs[2] = {
	{ .name = VIMC_PDEV_NAME, .id = 0, .dev.release = vimc_dev_release },
	{ .name = VIMC_PDEV_NAME, .id = 1, .dev.release = vimc_dev_release },
};

static struct platform_driver vimc_pdrv = {
	.probe		= vimc_probe,
	.remove		= vimc_remove,
	.driver		= {
		.name	= VIMC_PDEV_NAME,
	},
};

static int __init vimc_init(void)
{
	int ret;
	int i;

	for (i = 0; i < ARRAY_SIZE(vimc_pdevs); i++) {
		ret = platform_device_register(&vimc_pdevs[i]);
		if (ret) {
			platform_device_put(&vimc_pdevs[i]);
			while (--i >= 0)
				platform_device_unregister(&vimc_pdevs[i]);
			return ret;
		}
	}
	ret = platform_driver_register(&vimc_pdrv);
	if (ret) {
		for (i = 0; i < ARRAY_SIZE(vimc_pdevs); i++)
			platform_device_unregister(&vimc_pdevs[i]);
		return ret;
	}
	return 0;
}

static void __exit vimc_exit(void)
{
	int i;

	platform_driver_unregister(&vimc_pdrv);
	for (i = 0; i < ARRAY_SIZE(vimc_pdevs); i++)
		platform_device_unregister(&vimc_pdevs[i]);
}

module_init(vimc_init);
module_exit(vimc_exit);

MODULE_DESCRIPTION("Virtual Media Controller Driver (VIMC), two instances for edgetrack's tests");
MODULE_LICENSE("GPL");
EOF_VIMC
printf 'vimc-y := vimc-core.o vimc-common.o vimc-streamer.o vimc-capture.o vimc-debayer.o \\\n  vimc-scaler.o vimc-sensor.o vimc-lens.o\nobj-m := vimc.o\n' > "$work/vimc/Kbuild"

# gpio-sim links against irq_sim's exports: build irq_sim first and hand over its symbols.
make -s -C "$headers" M="$work/irq_sim" modules
make -s -C "$headers" M="$work/gpio_sim" KBUILD_EXTRA_SYMBOLS="$work/irq_sim/Module.symvers" modules
make -s -C "$headers" M="$work/vimc" modules

mkdir -p "$out_dir"
cp "$work/irq_sim/irq_sim.ko" "$work/gpio_sim/gpio-sim.ko" "$work/vimc/vimc.ko" "$out_dir/"
echo "$stamp" > "$out_dir/stamp"
